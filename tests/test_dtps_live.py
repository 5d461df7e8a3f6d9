"""A robot over DTPS, against dtps-http's own server: the kit reaches it as duckietown-sdk does, no ROS.

The robot (``dtps_robot.py``) is dtps-http's server on loopback, publishing the bundled recording's frames as
``duckietown_messages`` ``CompressedImage`` on ``ROBOT/sensor/camera/front_center/jpeg`` beside the camera's
``CameraIntrinsicCalibration``, with a key-value store's calibration queues. What is checked is what a user
gets: the command's exit, its words, the file written, what the robot holds after COMMIT.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from dtps_robot import DtpsRobotServer, silent_port

from dtscal_lib import calib_files
from dtscal_lib import duckietown as dt
from dtscal_lib.dtps_link import parse_dtps_spec
from dtscal_lib.errors import SourceError
from dtscal_lib.robot import CommitError, commit_dtps
from dtscal_lib.sources.live import DtpsLive, LiveFrames, open_live

ROOT = Path(__file__).resolve().parent.parent
DTSCAL = [sys.executable, "-m", "dtscal_lib.cli"]


def dtscal(*args, timeout=240) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([*DTSCAL, *args], capture_output=True, text=True, timeout=timeout, env=env, check=False)


@pytest.fixture(scope="module")
def committed(tmp_path_factory):
    """``dtscal calibrate-intrinsics --source dtps:testbot@127.0.0.1:PORT --commit`` against a running robot."""
    out = tmp_path_factory.mktemp("dtps") / "calibrations"
    with DtpsRobotServer(fps=40, step=3) as robot:
        proc = dtscal("calibrate-intrinsics", "--source", robot.spec, "--kvstore", robot.kvstore, "--out", str(out),
                      "--commit", "--max-seconds", "120", "--quiet")
        stored = dict(robot.stored)
    return proc, out, stored


@pytest.mark.slow  # ~15 s: the command calibrates from the live stream
def test_cli_calibrates_a_robot_over_dtps_and_commits_to_its_kvstore(committed):
    proc, out, stored = committed
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    path = out / "camera_intrinsic" / "testbot.yaml"
    assert path.is_file(), proc.stdout
    calib = calib_files.load_intrinsics(path)
    assert 300 < calib.K[0, 0] < 320, calib.K  # the recording is rendered through fx 307.7
    # the robot holds exactly the file's content, where its key-value store keeps camera_intrinsic/<ROBOT>.yaml
    assert stored["camera_intrinsic"] == calib.to_dict()
    assert "committed to testbot: stored as /data/config/calibrations/camera_intrinsic/testbot.yaml" in proc.stdout


def test_a_refused_commit_is_said_and_nothing_is_claimed(tmp_path):
    path = calib_files.save_intrinsics(calib_files.IntrinsicCalibration.from_dict(dt.DEFAULT_INTRINSICS), tmp_path,
                                       "testbot")
    with DtpsRobotServer(refuse=True, step=40) as robot:
        link = parse_dtps_spec(robot.spec[5:], kvstore=robot.kvstore)
        with pytest.raises(CommitError) as exc:
            commit_dtps(link, path, timeout=10)
        assert robot.stored == {}
    text = str(exc.value)
    assert "refused" in text and "403" in text and "this robot does not take calibrations" in text
    assert f"scp {path} duckie@testbot.local:/data/config/calibrations/camera_intrinsic/testbot.yaml" in text


def test_commit_stores_the_file_on_the_robot_and_checks_it_back(tmp_path):
    path = calib_files.save_intrinsics(calib_files.IntrinsicCalibration.from_dict(dt.DEFAULT_INTRINSICS), tmp_path,
                                       "testbot")
    with DtpsRobotServer(step=40) as robot:
        said = commit_dtps(parse_dtps_spec(robot.spec[5:], kvstore=robot.kvstore), path, timeout=10)
        deadline = time.monotonic() + 5
        while "camera_intrinsic" not in robot.stored and time.monotonic() < deadline:
            time.sleep(0.05)
    assert robot.stored["camera_intrinsic"] == calib_files.load_intrinsics(path).to_dict()
    assert said.startswith("stored as /data/config/calibrations/camera_intrinsic/testbot.yaml on testbot")


def test_a_store_that_keeps_something_else_is_not_called_a_commit(tmp_path):
    path = calib_files.save_intrinsics(calib_files.IntrinsicCalibration.from_dict(dt.DEFAULT_INTRINSICS), tmp_path,
                                       "testbot")
    with DtpsRobotServer(step=40, keep_other=True) as robot, pytest.raises(CommitError, match="did not keep"):
        commit_dtps(parse_dtps_spec(robot.spec[5:], kvstore=robot.kvstore), path, timeout=10)


def test_the_live_source_reads_frames_and_the_robots_intrinsics_then_sees_the_robot_go_away():
    with DtpsRobotServer(fps=30, step=5) as robot, open_live(robot.spec) as cam:
        assert isinstance(cam, DtpsLive)
        frame = cam.latest(timeout=15)
        assert frame is not None and frame.image.shape == (480, 640, 3), cam.status
        assert cam.robot_intrinsics["K"][0] == pytest.approx(307.7379294605756)
        robot.go_away()
        deadline = time.monotonic() + 15
        while cam.status.state == "running" and time.monotonic() < deadline:
            time.sleep(0.1)
        st = cam.status
        assert st.state == "ended", st
        assert "stopped answering" in st.message and "press Reconnect" in st.message
        assert cam.latest(after=-1, timeout=0).index == st.frames - 1 or cam.latest(timeout=0) is not None


def test_a_robot_that_never_answers_is_said_in_time():
    with silent_port() as port:
        cam = DtpsLive(parse_dtps_spec(f"nobot@127.0.0.1:{port}"), connect_seconds=1.0)
        with cam:
            assert cam.latest(timeout=10) is None
            st = cam.status
    assert st.state == "error" and "did not answer within 1 s" in st.message and "ping 127.0.0.1" in st.message


@pytest.mark.parametrize("mode, reason", [("png", "not_jpeg_png"), ("garbage", "unsupported_format")])
def test_frames_that_are_not_jpeg_are_counted_and_the_command_says_why(mode, reason):
    with DtpsRobotServer(mode=mode, step=20) as robot:
        frames = LiveFrames(robot.spec, max_seconds=30, say=lambda _m: None)
        with pytest.raises(SourceError) as exc:
            list(frames)
    text = str(exc.value)
    assert "none is a JPEG frame" in text and reason in text


def test_a_wrong_dtps_spec_says_how_to_write_one():
    with pytest.raises(SourceError, match="dtps:ROBOT"):
        open_live("dtps:not a robot")


def test_an_extrinsic_file_goes_to_its_own_key(tmp_path):
    path = calib_files.save_extrinsics(dt.default_H(), tmp_path, "testbot")
    with DtpsRobotServer(step=40) as robot:
        said = commit_dtps(parse_dtps_spec(robot.spec[5:], kvstore=robot.kvstore), path, kind="camera_extrinsic",
                           timeout=10)
        deadline = time.monotonic() + 5
        while "camera_extrinsic" not in robot.stored and time.monotonic() < deadline:
            time.sleep(0.05)
    assert robot.stored == {"camera_extrinsic": {"homography": pytest.approx(dt.DEFAULT_HOMOGRAPHY)}}
    assert said.startswith("stored as /data/config/calibrations/camera_extrinsic/testbot.yaml")
