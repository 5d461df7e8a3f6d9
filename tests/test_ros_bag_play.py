"""Bags against real ROS 1: ROS's own tools accept the kit's bags, and the kit reads ROS's bags.

Needs Debian's ROS packages (``scripts/install-ros.sh``). The private ``roscore`` (fixture
``roscore``), the process groups and the clean environment come from ``ros_env.py``.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import textwrap
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from dtscal_lib.sources import open_source, write_compressed_image_bag
from ros_env import SYSTEM_PYTHON, _free_port, _log, _ros_env, _ros_tool, _run, _started

pytestmark = pytest.mark.slow

TOPIC = "/autobot01/camera_node/image/compressed"


def _frames(n: int) -> list[bytes]:
    out = []
    for i in range(n):
        img = np.full((480, 640, 3), (40 + 15 * i, 120, 200 - 10 * i), np.uint8)
        cv2.rectangle(img, (30 + 40 * i, 100), (130 + 40 * i, 300), (255, 255, 255), -1)
        cv2.putText(img, f"#{i}", (300, 420), cv2.FONT_HERSHEY_SIMPLEX, 2, (0, 0, 0), 4)
        ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 85])
        assert ok
        out.append(buf.tobytes())
    return out


def _jpeg_files(jpegs: list[bytes], folder: Path) -> list[str]:
    """Write JPEG bytes as f0.jpg, f1.jpg, ... in ``folder``; their paths, for the ROS-side scripts."""
    files = []
    for i, b in enumerate(jpegs):
        p = folder / f"f{i}.jpg"
        p.write_bytes(b)
        files.append(str(p))
    return files


SUBSCRIBER = textwrap.dedent('''
    """Subscribe to a CompressedImage topic, record what arrives, write it as JSON."""
    import hashlib, json, sys, time
    import rospy
    from sensor_msgs.msg import CompressedImage

    topic, expected, out, timeout = sys.argv[1], int(sys.argv[2]), sys.argv[3], float(sys.argv[4])
    got = []

    def on_message(m):
        got.append({"format": m.format, "sha256": hashlib.sha256(bytes(m.data)).hexdigest(),
                    "stamp_ns": m.header.stamp.to_nsec(), "frame_id": m.header.frame_id,
                    "md5": m._md5sum, "type": m._type})

    rospy.init_node("dtscal_check_sub", anonymous=True, disable_signals=True)
    rospy.Subscriber(topic, CompressedImage, on_message, queue_size=1000)
    print("READY", flush=True)
    deadline = time.time() + timeout
    while len(got) < expected and time.time() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)  # catch any extra message
    with open(out, "w") as f:
        json.dump(got, f)
    print("GOT", len(got), flush=True)
''')


def _play_to_subscriber(env, bag, topic: str, n: int, tmp_path: Path) -> list[dict]:
    """``rosbag play`` a bag to a rospy subscriber on a real master; what the subscriber got."""
    script = tmp_path / "sub.py"
    script.write_text(SUBSCRIBER)
    received = tmp_path / "received.json"
    sub_log = tmp_path / "sub.log"
    with _started([SYSTEM_PYTHON, str(script), topic, str(n), str(received), "90"], env, sub_log) as sub:
        deadline = time.time() + 60
        while "READY" not in _log(sub_log):
            assert sub.poll() is None, f"subscriber died:\n{_log(sub_log)}"
            assert time.time() < deadline, f"subscriber not ready:\n{_log(sub_log)}"
            time.sleep(0.1)
        play = _run([_ros_tool("rosbag"), "play", "--quiet", "--wait-for-subscribers", "-d", "1", str(bag)], env)
        assert play.returncode == 0, play.stdout + play.stderr
        try:
            sub.wait(timeout=90)
        except subprocess.TimeoutExpired:
            pytest.fail(f"subscriber did not finish:\n{_log(sub_log)}")
    got = json.loads(received.read_text())
    assert len(got) == n, _log(sub_log)
    return got


def test_rosbag_info_and_play_accept_our_bag(roscore, tmp_path):
    import hashlib

    env = roscore
    jpegs = _frames(10)
    stamps = [1_700_000_000 * 10**9 + i * 33_333_333 for i in range(10)]
    bag = write_compressed_image_bag(tmp_path / "kit.bag", TOPIC, zip(stamps, jpegs), frame_id="camera_optical_frame")

    info = _run([_ros_tool("rosbag"), "info", "--yaml", str(bag)], env)
    assert info.returncode == 0, info.stderr
    meta = yaml.safe_load(info.stdout)
    assert meta["version"] == 2.0 and meta["messages"] == 10 and meta["indexed"] is True
    assert meta["topics"] == [{"topic": TOPIC, "type": "sensor_msgs/CompressedImage", "messages": 10}]
    assert meta["types"] == [{"type": "sensor_msgs/CompressedImage", "md5": "8f7a12909da2c9d3332d540a0977563f"}]
    human = _run([_ros_tool("rosbag"), "info", str(bag)], env)
    assert human.returncode == 0 and "10 msgs" in human.stdout

    got = _play_to_subscriber(env, bag, TOPIC, 10, tmp_path)
    for g, b, t in zip(got, jpegs, stamps):
        assert g["format"] == "jpeg"
        assert g["type"] == "sensor_msgs/CompressedImage" and g["md5"] == "8f7a12909da2c9d3332d540a0977563f"
        assert g["sha256"] == hashlib.sha256(b).hexdigest()  # byte-identical JPEG
        assert g["stamp_ns"] == t and g["frame_id"] == "camera_optical_frame"


ROS_WRITER = textwrap.dedent('''
    """Write JPEG files into a bag with ROS's own rosbag.Bag writer."""
    import sys
    import rosbag, rospy
    from sensor_msgs.msg import CompressedImage

    out, topic, compression = sys.argv[1], sys.argv[2], sys.argv[3]
    files = sys.argv[4:]
    with rosbag.Bag(out, "w", compression=compression, chunk_threshold=40000) as bag:
        for i, path in enumerate(files):
            m = CompressedImage()
            m.header.seq = i
            m.header.stamp = rospy.Time(1600000000 + i, 5000)
            m.header.frame_id = "cam"
            m.format = "jpeg"
            m.data = open(path, "rb").read()
            bag.write(topic, m, t=rospy.Time(1600000000 + i, 5000))
''')


@pytest.mark.parametrize("compression", ["none", "bz2", "lz4"])
def test_bag_written_by_ros_is_read(ros_ok, tmp_path, compression):
    jpegs = _frames(8)
    files = _jpeg_files(jpegs, tmp_path)
    script = tmp_path / "writer.py"
    script.write_text(ROS_WRITER)
    bag = tmp_path / f"ros_{compression}.bag"
    env = _ros_env(tmp_path / "home", _free_port())
    res = _run([SYSTEM_PYTHON, str(script), str(bag), TOPIC, compression, *files], env)
    assert res.returncode == 0, res.stdout + res.stderr

    src = open_source(bag)
    assert src.topic == TOPIC and len(src) == 8 and not src.truncated
    frames = list(src)
    for i, (f, b) in enumerate(zip(frames, jpegs)):
        assert f.ok
        np.testing.assert_array_equal(f.image, cv2.imdecode(np.frombuffer(b, np.uint8), cv2.IMREAD_COLOR))
        assert f.stamp == pytest.approx(1600000000 + i + 5e-6, abs=1e-6)

    # the same bag cut short still gives its first frames, through the sequential reader
    cut = tmp_path / "cut.bag"
    cut.write_bytes(bag.read_bytes()[: int(bag.stat().st_size * 0.7)])
    frames = list(open_source(cut))
    assert frames[-1].error is not None and frames[-1].error.reason == "truncated"
    assert len(frames) >= 3 and all(f.ok for f in frames[:-1])


PUBLISHER = textwrap.dedent('''
    """Publish JPEG files on a CompressedImage topic once a subscriber is there."""
    import sys, time
    import rospy
    from sensor_msgs.msg import CompressedImage

    topic, files = sys.argv[1], sys.argv[2:]
    rospy.init_node("dtscal_check_pub", anonymous=True, disable_signals=True)
    pub = rospy.Publisher(topic, CompressedImage, queue_size=100)
    deadline = time.time() + 60
    while pub.get_num_connections() == 0 and time.time() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)
    for i, path in enumerate(files):
        m = CompressedImage()
        m.header.seq = i
        m.header.stamp = rospy.Time(1650000000 + i, 0)
        m.format = "jpeg"
        m.data = open(path, "rb").read()
        pub.publish(m)
        time.sleep(0.1)
    print("PUBLISHED", len(files), flush=True)
    time.sleep(1.0)
''')


def test_rosbag_record_output_is_read(roscore, tmp_path):
    env = roscore
    jpegs = _frames(6)
    files = _jpeg_files(jpegs, tmp_path)
    pub_script = tmp_path / "pub.py"
    pub_script.write_text(PUBLISHER)

    # 1. a recording that ends normally (--limit): indexed, read by rosbags
    out = tmp_path / "recorded.bag"
    rec_log = tmp_path / "record.log"
    with _started([_ros_tool("rosbag"), "record", "-O", str(out), "--limit=6", TOPIC], env, rec_log) as rec:
        pub = _run([SYSTEM_PYTHON, str(pub_script), TOPIC, *files], env)
        assert pub.returncode == 0 and "PUBLISHED 6" in pub.stdout, pub.stdout + pub.stderr
        try:
            rec.wait(timeout=60)
        except subprocess.TimeoutExpired:
            pytest.fail(f"rosbag record did not stop after 6 messages:\n{_log(rec_log)}")
    src = open_source(out)
    assert src.topic == TOPIC and len(src) == 6 and not src.truncated
    frames = list(src)
    for i, (f, b) in enumerate(zip(frames, jpegs)):
        assert f.ok, f.error
        np.testing.assert_array_equal(f.image, cv2.imdecode(np.frombuffer(b, np.uint8), cv2.IMREAD_COLOR))
        assert f.stamp == pytest.approx(1650000000 + i)

    # 2. a recording killed with SIGKILL (robot unplugged): `.bag.active`, no index
    killed = tmp_path / "killed.bag"
    kill_log = tmp_path / "killed.log"
    with _started([_ros_tool("rosbag"), "record", "-O", str(killed), TOPIC], env, kill_log) as rec:
        pub = _run([SYSTEM_PYTHON, str(pub_script), TOPIC, *files], env)
        assert pub.returncode == 0, pub.stdout + pub.stderr
        time.sleep(1.0)
        os.killpg(os.getpgid(rec.pid), signal.SIGKILL)
        rec.wait(timeout=10)
    active = tmp_path / "killed.bag.active"
    assert active.exists(), sorted(p.name for p in tmp_path.iterdir())
    src = open_source(active)
    assert src.truncated
    frames = list(src)
    assert frames[-1].error is not None and frames[-1].error.reason == "truncated"
    good = frames[:-1]
    # whatever reached the disk before the kill is read back intact, in order (the last
    # message may still have been in rosbag's write buffer)
    assert len(good) >= 3, frames[-1].error
    for i, f in enumerate(good):
        assert f.ok
        np.testing.assert_array_equal(f.image, cv2.imdecode(np.frombuffer(jpegs[i], np.uint8), cv2.IMREAD_COLOR))


def test_shipped_session_plays_with_ros(roscore, tmp_path):
    """The bundled recording itself is a bag ROS's own tools accept and publish."""
    from dtscal_lib import datasets

    env = roscore
    topic = "/synthbot/camera_node/image/compressed"
    for name, n in (("intrinsics.bag", 406), ("extrinsics.bag", 5)):
        info = _run([_ros_tool("rosbag"), "info", "--yaml", str(datasets.session_dir() / name)], env)
        assert info.returncode == 0, info.stderr
        meta = yaml.safe_load(info.stdout)
        assert meta["messages"] == n and meta["topics"][0]["topic"] == topic
    got = _play_to_subscriber(env, datasets.session_dir() / "extrinsics.bag", topic, 5, tmp_path)
    expected = [d for _, _, d in datasets.read_bag_jpegs(datasets.session_dir() / "extrinsics.bag")]
    assert [g["sha256"] for g in got] == [__import__("hashlib").sha256(d).hexdigest() for d in expected]
