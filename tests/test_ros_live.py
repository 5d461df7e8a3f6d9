"""The live ROS 1 path against real ROS: a private ``roscore``, ROS's own ``rosbag play`` of the bundled
recording onto ``/synthbot/camera_node/image/compressed``, and a small camera node (rospy) that serves
``set_camera_info`` and writes what it receives as the robot's ``camera_intrinsic/<ROBOT>.yaml``, as the
Duckiebot's camera node does. The kit calibrates from the live topic, commits, and the robot-side file
is checked against the ground truth of the recording. Then the faults: the master killed mid-session,
the bag ending, COMMIT with no service or no master.

Helpers (roscore, process groups, the ROS environment, the camera node) come from ``ros_env.py``, the
fixtures ``roscore`` and ``file_server`` from conftest.py.
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from live_fakes import write_test_bag
from ros_env import (CAMERA_NODE, ROBOT, SYSTEM_PYTHON, _free_port, _kill_master, _log, _ros_tool, _run, _started,
                     _subscribers, _wait, running_roscore)

from dtscal_lib import calib_files, datasets
from dtscal_lib import duckietown as dt
from dtscal_lib.robot import CommitError, commit_intrinsics
from dtscal_lib.sources import open_live

pytestmark = pytest.mark.slow

TOPIC = f"/{ROBOT}/camera_node/image/compressed"

def _kit_env(env) -> dict:
    """The kit's own environment (its venv) pointed at the test's master."""
    out = dict(os.environ)
    out.update({k: env[k] for k in ("ROS_MASTER_URI", "ROS_HOSTNAME", "ROS_HOME", "ROS_LOG_DIR")})
    return out


def _cli_on_live_topic(env, args: list[str], bag: str, tmp_path: Path, *, loop: bool = False,
                       timeout: float = 200) -> dict:
    """Run ``dtscal ARGS --source ros:ROBOT --json`` (the kit's own venv), play ``bag`` once it subscribed."""
    cmd = [sys.executable, "-m", "dtscal_lib.cli", *args, "--source", f"ros:{ROBOT}", "--json", "-q"]
    err_log = tmp_path / "cli.err"
    with err_log.open("wb") as err:
        cli = subprocess.Popen(cmd, env=_kit_env(env), stdout=subprocess.PIPE, stderr=err, start_new_session=True)
    try:
        _wait(lambda: _subscribers(env, TOPIC) > 0 or cli.poll() is not None, 60, "the kit to subscribe")
        assert cli.poll() is None, _log(err_log)
        play = [_ros_tool("rosbag"), "play", "--quiet", *(["--loop"] if loop else []),
                str(datasets.session_dir() / bag)]
        with _started(play, env, tmp_path / "play.log"):
            stdout, _ = cli.communicate(timeout=timeout)
    finally:
        if cli.poll() is None:
            os.killpg(cli.pid, signal.SIGKILL)
            cli.wait()
    assert cli.returncode == 0, _log(err_log)
    return json.loads(stdout)


@pytest.fixture
def camera_node(roscore, tmp_path):
    robot_root = tmp_path / "robot" / "data" / "config" / "calibrations"
    script = tmp_path / "camera_node.py"
    script.write_text(CAMERA_NODE)
    log = tmp_path / "camera_node.log"
    with _started([SYSTEM_PYTHON, str(script), ROBOT, str(robot_root)], roscore, log) as node:
        _wait(lambda: "READY" in _log(log) or node.poll() is not None, 60, "the camera node")
        assert node.poll() is None, _log(log)
        yield robot_root


def test_calibrate_from_live_topic_and_commit(roscore, camera_node, tmp_path):
    env = roscore
    out = tmp_path / "calibrations"
    run = _cli_on_live_topic(env, ["calibrate-intrinsics", "--commit", "--out", str(out), "--max-seconds", "150"],
                             "intrinsics.bag", tmp_path, loop=True, timeout=200)  # a camera streams on
    assert run["robot"] == ROBOT and run["samples_used"] >= 20, run
    assert run["commit"].startswith("Write to ")
    robot_file = camera_node / "camera_intrinsic" / f"{ROBOT}.yaml"
    assert run["commit"] == f"Write to {robot_file}"
    robot_side = calib_files.load_intrinsics(robot_file)  # what the robot would load on its next start
    local = calib_files.load_intrinsics(out / "camera_intrinsic" / f"{ROBOT}.yaml")
    np.testing.assert_allclose(robot_side.K, local.K, rtol=1e-12)
    np.testing.assert_allclose(robot_side.P, local.P, rtol=1e-12)
    truth = np.array(datasets.load_truth()["camera"]["K"], dtype=float)
    K = robot_side.K
    for name, got, want in (("fx", K[0, 0], truth[0, 0]), ("fy", K[1, 1], truth[1, 1]),
                            ("cx", K[0, 2], truth[0, 2]), ("cy", K[1, 2], truth[1, 2])):
        print(f"{name}: committed {got:.3f}, truth {want:.3f}, error {100 * abs(got - want) / want:.3f} %")
        assert abs(got - want) / want < 0.003, f"{name}: committed {got:.3f}, truth {want:.3f}"
    print(f"samples {run['samples_used']}, frames {run['frames']}")


def test_master_killed_mid_session_then_reconnect(ros_ok, tmp_path):
    home = tmp_path / "home"
    port = _free_port()
    bag = str(datasets.session_dir() / "intrinsics.bag")
    with running_roscore(home, port) as env, \
            _started([_ros_tool("rosbag"), "play", "--quiet", "--loop", bag], env, tmp_path / "p1.log"):
        cam = open_live(f"ros:{ROBOT}", master_uri=env["ROS_MASTER_URI"]).start()
        try:
            first = cam.latest(timeout=60)
            assert first is not None and first.ok, cam.status
            _wait(lambda: cam.status.frames >= 10, 30, "ten frames")
            _kill_master(env)
            st = _wait(lambda: cam.status if cam.status.state == "error" else None, 20, "the error status")
            assert "went away" in st.message and env["ROS_MASTER_URI"] in st.message and "Reconnect" in st.message
            kept = cam.latest(timeout=0)
            assert kept is not None and kept.ok  # the last frame is still there
            frames_before = cam.status.frames
        except BaseException:
            cam.close()
            raise
    # the robot comes back: a new master on the same port, the camera publishing again
    try:
        with running_roscore(home, port) as env, \
                _started([_ros_tool("rosbag"), "play", "--quiet", "--loop", bag], env, tmp_path / "p2.log"):
            cam.reconnect()
            again = cam.latest(after=kept.index, timeout=60)
            assert again is not None and again.ok, cam.status
            assert cam.status.state == "running" and cam.status.frames > frames_before
    finally:
        cam.close()


def test_bag_end_is_reported_and_frames_resume(roscore, tmp_path):
    env = roscore
    bag = str(datasets.session_dir() / "extrinsics.bag")
    with open_live(f"ros:{ROBOT}", master_uri=env["ROS_MASTER_URI"]) as cam:
        _wait(lambda: _subscribers(env, TOPIC) > 0, 60, "the helper to subscribe")
        assert cam.status.state == "connecting"
        play = _run([_ros_tool("rosbag"), "play", "--quiet", "-d", "0.5", bag], env)
        assert play.returncode == 0, play.stdout + play.stderr
        st = _wait(lambda: cam.status if cam.status.state == "ended" else None, 20, "the ended status")
        assert "nobody publishes" in st.message and TOPIC in st.message
        assert 1 <= st.frames <= 5 and st.bad == {}
        last = cam.latest(timeout=0)
        assert last is not None and last.ok
        assert cam.latest(after=last.index, timeout=5) is None  # nothing new, and no waiting the full timeout
        cam.reconnect()
        _wait(lambda: _subscribers(env, TOPIC) > 0, 60, "the helper to subscribe again")
        play = _run([_ros_tool("rosbag"), "play", "--quiet", "-d", "0.5", bag], env)
        assert play.returncode == 0
        again = cam.latest(after=last.index, timeout=10)
        assert again is not None and again.index > last.index


def test_commit_without_service_or_master_is_a_clear_error(roscore, tmp_path):
    calib = calib_files.IntrinsicCalibration.from_dict(dt.DEFAULT_INTRINSICS, "default")
    path = calib_files.save_intrinsics(calib, tmp_path / "cal", "nobot")
    before = hashlib.sha256(path.read_bytes()).hexdigest()
    with pytest.raises(CommitError) as e:
        commit_intrinsics("nobot", path, master_uri=roscore["ROS_MASTER_URI"], timeout=2)
    msg = str(e.value)
    # the 2 s wait for the service ran out (the reason, not the elapsed time, is what is checked)
    assert "no service /nobot/camera_node/set_camera_info" in msg and "within 2 s" in msg and "camera node" in msg
    assert f"{path} is kept" in msg and "scp" in msg
    with pytest.raises(CommitError, match="cannot reach the ROS master"):
        commit_intrinsics("nobot", path, master_uri=f"http://127.0.0.1:{_free_port()}", timeout=2)
    assert hashlib.sha256(path.read_bytes()).hexdigest() == before  # the local file is intact
    # and the result can still be saved elsewhere
    again = calib_files.save_intrinsics(calib_files.load_intrinsics(path), tmp_path / "other", "nobot")
    assert again.read_bytes() == path.read_bytes()
    bad = tmp_path / "bad.yaml"
    bad.write_text("image_width: 640\n")
    with pytest.raises(CommitError, match="nothing was sent"):
        commit_intrinsics("nobot", bad, master_uri=roscore["ROS_MASTER_URI"], timeout=2)


def test_ros_missing_is_a_clear_error(monkeypatch, tmp_path):
    monkeypatch.setenv("DTSCAL_ROS_PYTHON", str(tmp_path / "no-python"))
    from dtscal_lib.errors import SourceError

    with pytest.raises(SourceError, match="install-ros.sh"):
        open_live("ros:autobot01")
    calib = calib_files.IntrinsicCalibration.from_dict(dt.DEFAULT_INTRINSICS, "default")
    path = calib_files.save_intrinsics(calib, tmp_path, "autobot01")
    with pytest.raises(CommitError, match="cannot talk ROS"):
        commit_intrinsics("autobot01", path)


def test_helper_uses_newest_frame_only(roscore, tmp_path):
    """A consumer that takes one frame, then comes back after the whole recording has played, gets the
    newest frame received, never the next one of a queue (counts, not a rate: a loaded machine may
    receive fewer of the bag's frames, and the answer is still the newest of those it received)."""
    env = roscore
    bag = str(datasets.session_dir() / "intrinsics.bag")
    with open_live(f"ros:{ROBOT}", master_uri=env["ROS_MASTER_URI"]) as cam:
        _wait(lambda: _subscribers(env, TOPIC) > 0, 60, "the helper to subscribe")
        play = subprocess.Popen([_ros_tool("rosbag"), "play", "--quiet", bag], env=env,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        try:
            first = cam.latest(timeout=30)
            assert first is not None
            assert play.wait(timeout=600) == 0  # a safety net: the bag plays in about 20 s
        finally:
            if play.poll() is None:
                os.killpg(play.pid, signal.SIGKILL)
                play.wait()
        back = cam.latest(after=first.index, timeout=5)  # the consumer is back: the newest frame so far
        newest = back
        while (newer := cam.latest(after=newest.index, timeout=2)) is not None:  # frames still in the pipe
            newest = newer
        st = cam.status
    assert st.bad == {} and st.frames > first.index + 10, st  # many frames arrived while the consumer was away
    assert back is not None and back.index > first.index + 10, (first.index, back)  # skipped, not queued
    assert newest.index == st.frames - 1, (newest.index, st)  # the last frame handed out is the last received
    assert Path(bag).exists()


def test_cli_extrinsics_from_live_topic_and_upload(roscore, file_server, tmp_path):
    env = roscore
    base, stored = file_server
    truth = datasets.load_truth()["camera"]
    calib = calib_files.IntrinsicCalibration(
        camera_name=f"/{ROBOT}/camera_node", width=640, height=480, K=np.array(truth["K"]),
        distortion_model="plumb_bob", D=np.array(truth["dist"]), R=np.eye(3), P=np.array(truth["P"]))
    intr = calib_files.save_intrinsics(calib, tmp_path / "in", ROBOT)
    out = tmp_path / "calibrations"
    url = f"{base}/files/data/config/calibrations/camera_extrinsic/{ROBOT}.yaml"
    run = _cli_on_live_topic(env, ["calibrate-extrinsics", "--intrinsics", str(intr), "--out", str(out), "--commit",
                                   "--upload-url", url, "--max-seconds", "90"], "extrinsics.bag", tmp_path,
                             loop=True, timeout=120)
    local = out / "camera_extrinsic" / f"{ROBOT}.yaml"
    assert run["commit"] == f"uploaded {local} to {url} (HTTP 200)"
    assert stored[url[len(base):]] == local.read_bytes()
    assert run["corner_residual_mm"]["max"] < 3.0, run
    # against the truth: the board corners' rectified pixels (from the true homography, same P) to the ground
    ext = datasets.load_truth()["extrinsics"]
    ground = np.asarray(ext["ground_points"], float)
    pix = np.linalg.inv(np.asarray(ext["homography"], float)) @ np.c_[ground, np.ones(len(ground))].T
    back = np.asarray(run["homography"], float).reshape(3, 3) @ pix
    err_mm = 1000 * np.linalg.norm((back[:2] / back[2]).T - ground, axis=1)
    assert err_mm.max() < 3.0, f"worst corner {err_mm.max():.2f} mm"
    print(f"extrinsics from the live topic: worst board corner {err_mm.max():.2f} mm from the truth")


def test_cli_commit_without_service_keeps_the_written_file(roscore, tmp_path):
    out = tmp_path / "calibrations"
    cmd = [sys.executable, "-m", "dtscal_lib.cli", "calibrate-intrinsics", "--source",
           str(datasets.session_dir() / "intrinsics.bag"), "--out", str(out), "--robot", "nobot", "--commit",
           "--master-uri", roscore["ROS_MASTER_URI"], "--commit-timeout", "2", "-q"]
    res = subprocess.run(cmd, env=_kit_env(roscore), capture_output=True, text=True, timeout=300, check=False)
    assert res.returncode == 2, res.stdout + res.stderr
    assert "no service /nobot/camera_node/set_camera_info" in res.stderr and "Traceback" not in res.stderr
    written = out / "camera_intrinsic" / "nobot.yaml"
    assert f"{written} is kept" in res.stderr
    assert "calibrated nobot" in res.stdout and f"wrote {written}" in res.stdout  # the result was printed
    calib_files.load_intrinsics(written)  # the calibration itself was saved


def test_corrupt_frames_over_ros_are_counted(roscore, tmp_path):
    """JPEGs damaged on the way (cut short) arrive over ROS: counted by reason, never handed out."""
    env = roscore
    # published on /testbot/camera_node/image/compressed
    bag = write_test_bag(tmp_path / "bad.bag", 10, fps=10, corrupt={2, 5, 6})
    with open_live("ros:testbot", master_uri=env["ROS_MASTER_URI"]) as cam:
        _wait(lambda: _subscribers(env, "/testbot/camera_node/image/compressed") > 0, 60, "the helper to subscribe")
        play = _run([_ros_tool("rosbag"), "play", "--quiet", "-d", "0.5", bag], env)
        assert play.returncode == 0, play.stdout + play.stderr
        st = _wait(lambda: cam.status if cam.status.state == "ended" else None, 20, "the ended status")
        assert st.frames == 10 and st.bad == {"corrupt_jpeg": 3}, st
        last = cam.latest(timeout=0)
        assert last is not None and last.ok and last.index == 9
