"""A ``ros:`` source that gets no frame says why, in one sentence with the fix, against a real roscore.

The faults a class meets with a robot: ``ROS_MASTER_URI`` unset (nothing on this computer), a robot
name that does not resolve, a closed port, the master up without the camera topic (the robot there
without its camera node, or no robot at all), a robot name the master does not know (the robots
whose camera it has are listed), and ``ROS_IP`` naming an address that is not this computer's (the
robot would send its frames there). The status line (through the source's status hook, no frame
needed) and the command line say it. The tests assert the sentence, never how fast it came; the
time to the sentence is a benchmark figure (benchmarks/bench_ros_diagnosis.py).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from ros_env import ROBOT, _free_port, _log, _ros_tool, _started, _wait

from dtscal_lib import datasets
from dtscal_lib.sources import live, open_live

pytestmark = pytest.mark.slow
TOPIC = f"/{ROBOT}/camera_node/image/compressed"


def _sentence(monkeypatch, spec: str, env: dict, *, master: str | None = None, wait_for=("error",)) -> str:
    """Start ``spec`` with ``env`` as the ROS environment; the first diagnosis its status hook hears."""
    for k in ("ROS_MASTER_URI", "ROS_IP", "ROS_HOSTNAME"):
        monkeypatch.delenv(k, raising=False)
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    heard = []
    cam = open_live(spec, master_uri=master)
    cam.add_status_listener(heard.append)
    try:
        cam.start()
        _wait(lambda: any(st.state in wait_for and not st.message.startswith("connecting to ") for st in heard),
              30, f"a diagnosis of {spec}")
        st = next(st for st in heard if st.state in wait_for and not st.message.startswith("connecting to "))
        assert cam.status.frames == 0
        return st.message
    finally:
        cam.close()


def test_master_uri_unset_and_no_master_here(ros_ok, monkeypatch):
    monkeypatch.setattr(live, "DEFAULT_MASTER", f"http://127.0.0.1:{_free_port()}")  # nothing listens there
    msg = _sentence(monkeypatch, f"ros:{ROBOT}", {})
    assert msg.startswith("ROS_MASTER_URI is not set and no ROS master runs on this computer: set it to your "
                          "robot's master")
    assert "export ROS_MASTER_URI=http://ROBOT.local:11311" in msg and msg.endswith("then press Reconnect")


def test_robot_name_that_does_not_resolve(ros_ok, monkeypatch):
    msg = _sentence(monkeypatch, f"ros:{ROBOT}", {"ROS_MASTER_URI": "http://nosuchrobot.invalid:11311"})
    assert msg.startswith("the robot's name nosuchrobot.invalid in ROS_MASTER_URI=http://nosuchrobot.invalid:11311 "
                          "does not resolve")
    assert "ping nosuchrobot.invalid" in msg


def test_closed_port(ros_ok, monkeypatch):
    port = _free_port()
    msg = _sentence(monkeypatch, f"ros:{ROBOT}", {"ROS_MASTER_URI": f"http://127.0.0.1:{port}"})
    assert msg.startswith(f"nothing listens on port {port} of 127.0.0.1")
    assert "no ROS master runs on it; start the robot's ROS" in msg


def test_master_up_but_no_camera_at_all(roscore, monkeypatch):
    msg = _sentence(monkeypatch, f"ros:{ROBOT}", {"ROS_MASTER_URI": roscore["ROS_MASTER_URI"],
                                                   "ROS_HOSTNAME": "127.0.0.1"}, wait_for=("connecting",))
    assert msg.startswith(f"nobody publishes {TOPIC} on the ROS master at {roscore['ROS_MASTER_URI']}, and no "
                          "robot's camera is on it: start the robot's camera node")


def test_robot_there_without_its_camera_topic(roscore, monkeypatch, tmp_path):
    pub = [_ros_tool("rostopic"), "pub", "-r", "2", f"/{ROBOT}/wheels_driver_node/note", "std_msgs/String", "hi"]
    with _started(pub, roscore, tmp_path / "pub.log") as proc:
        _wait(lambda: f"/{ROBOT}/wheels_driver_node/note" in _topics(roscore) or proc.poll() is not None, 60,
              "rostopic pub")
        assert proc.poll() is None, _log(tmp_path / "pub.log")
        msg = _sentence(monkeypatch, f"ros:{ROBOT}", {"ROS_MASTER_URI": roscore["ROS_MASTER_URI"],
                                                       "ROS_HOSTNAME": "127.0.0.1"}, wait_for=("connecting",))
    assert msg.startswith(f"the robot {ROBOT} is on the ROS master at {roscore['ROS_MASTER_URI']} but nobody "
                          f"publishes {TOPIC}: start its camera node")


def _topics(env) -> set:
    import xmlrpc.client

    _c, _m, state = xmlrpc.client.ServerProxy(env["ROS_MASTER_URI"]).getSystemState("/dtscal_test")
    return {t for t, nodes in state[0] if nodes}


@pytest.fixture
def playing(roscore, tmp_path):
    """The recording played onto the robot's camera topic (what a Duckiebot publishes)."""
    play = [_ros_tool("rosbag"), "play", "--quiet", "--loop", str(datasets.session_dir() / "intrinsics.bag")]
    with _started(play, roscore, tmp_path / "play.log") as proc:
        _wait(lambda: TOPIC in _topics(roscore) or proc.poll() is not None, 60, "rosbag play")
        assert proc.poll() is None, _log(tmp_path / "play.log")
        yield roscore


def test_robot_name_the_master_does_not_know_lists_its_robots(playing, monkeypatch):
    msg = _sentence(monkeypatch, "ros:nosuchbot", {"ROS_MASTER_URI": playing["ROS_MASTER_URI"],
                                                    "ROS_HOSTNAME": "127.0.0.1"}, wait_for=("connecting",))
    assert msg == (f"the ROS master at {playing['ROS_MASTER_URI']} knows no robot named nosuchbot; it has the "
                   f"camera of {ROBOT}: use ros:{ROBOT}, then press Reconnect")


def test_ros_ip_that_is_not_this_computer(playing, monkeypatch):
    # 192.0.2.1 is TEST-NET-1 (RFC 5737): never an address of this computer
    msg = _sentence(monkeypatch, f"ros:{ROBOT}", {"ROS_MASTER_URI": playing["ROS_MASTER_URI"], "ROS_IP": "192.0.2.1"})
    assert msg.startswith("ROS_IP=192.0.2.1 is not an address of this computer, so the robot cannot send the "
                          "frames back (the connection hangs after registering): set it to this computer's address")


def test_a_good_connection_has_no_diagnosis(playing, monkeypatch):
    for k, v in {"ROS_MASTER_URI": playing["ROS_MASTER_URI"], "ROS_HOSTNAME": "127.0.0.1"}.items():
        monkeypatch.setenv(k, v)
    with open_live(f"ros:{ROBOT}") as cam:
        assert cam.latest(timeout=60) is not None, cam.status.message


def _cli(args: list[str], env: dict) -> subprocess.CompletedProcess:
    full = {k: v for k, v in os.environ.items() if k not in ("ROS_MASTER_URI", "ROS_IP", "ROS_HOSTNAME")}
    full.update(env)
    return subprocess.run([sys.executable, "-m", "dtscal_lib.cli", "calibrate-intrinsics", *args, "--no-write",
                           "-q"], env=full, capture_output=True, text=True, timeout=120,
                          cwd=Path(live.__file__).resolve().parents[2])  # this checkout's kit


def test_cli_says_the_sentence(playing, ros_ok):
    port = _free_port()
    res = _cli(["--source", f"ros:{ROBOT}", "--max-seconds", "20"], {"ROS_MASTER_URI": f"http://127.0.0.1:{port}"})
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert f"nothing listens on port {port} of 127.0.0.1" in res.stderr and "run the command again" in res.stderr
    res = _cli(["--source", "ros:nosuchbot", "--max-seconds", "6"],
               {"ROS_MASTER_URI": playing["ROS_MASTER_URI"], "ROS_HOSTNAME": "127.0.0.1"})
    assert "Traceback" not in res.stderr
    assert (f"dtscal: waiting: the ROS master at {playing['ROS_MASTER_URI']} knows no robot named nosuchbot; it has "
            f"the camera of {ROBOT}: use ros:{ROBOT}") in res.stderr


def test_notebook_status_line_shows_the_sentence_without_a_frame(playing, monkeypatch):
    """Notebook 06's calibrator: the status line says why, while no frame has come (connecting and error)."""
    from dtscal_lib.ui import LiveCalibrator

    monkeypatch.delenv("ROS_IP", raising=False)
    for k, v in {"ROS_MASTER_URI": playing["ROS_MASTER_URI"], "ROS_HOSTNAME": "127.0.0.1"}.items():
        monkeypatch.setenv(k, v)
    app = LiveCalibrator(open_live("ros:nosuchbot"))
    try:
        try:
            _wait(lambda: "knows no robot named nosuchbot" in app.status.value, 30, "the status line")
        except BaseException:
            pytest.fail(f"the status line says: {app.status.value}")
        assert f"use ros:{ROBOT}" in app.status.value and app.frames_seen == 0
    finally:
        app.close()
    port = _free_port()
    app = LiveCalibrator(open_live(f"ros:{ROBOT}", master_uri=f"http://127.0.0.1:{port}"))
    try:
        _wait(lambda: f"nothing listens on port {port}" in app.status.value, 30, "the status line")
        assert "could not connect to" in app.status.value and "source lost" not in app.status.value
    finally:
        app.close()
