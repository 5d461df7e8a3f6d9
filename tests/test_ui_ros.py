"""The live calibrator on a real ROS 1 topic: ``roscore``, ``rosbag play`` of the recording onto the
robot's camera topic, and a camera node whose ``set_camera_info`` writes the robot-side YAML.

The calibrator fills its bars from the topic, CALIBRATEs, COMMITs over ROS (the robot-side file is
within 0.3 % of the truth); then the master is killed: the UI says so and keeps every sample; a new
master comes up and RECONNECT resumes the stream.
"""

from __future__ import annotations

import numpy as np
import pytest
from ros_env import CAMERA_NODE, ROBOT, SYSTEM_PYTHON, _free_port, _kill_master, _log, _ros_tool, _started, _wait, \
    running_roscore

from dtscal_lib import calib_files, datasets
from dtscal_lib.sources import open_live
from dtscal_lib.ui import LiveCalibrator

pytestmark = pytest.mark.slow


def test_calibrator_commits_over_ros_and_survives_a_master_crash(ros_ok, tmp_path):
    home, port = tmp_path / "home", _free_port()
    bag = str(datasets.session_dir() / "intrinsics.bag")
    robot_root = tmp_path / "robot" / "data" / "config" / "calibrations"
    script = tmp_path / "camera_node.py"
    script.write_text(CAMERA_NODE)
    node_log = tmp_path / "camera_node.log"
    app = None
    try:
        with running_roscore(home, port) as env, \
                _started([_ros_tool("rosbag"), "play", "--quiet", "--loop", bag], env, tmp_path / "p1.log"), \
                _started([SYSTEM_PYTHON, str(script), ROBOT, str(robot_root)], env, node_log) as node:
            _wait(lambda: "READY" in _log(node_log) or node.poll() is not None, 60, "the camera node")
            app = LiveCalibrator(open_live(f"ros:{ROBOT}", master_uri=env["ROS_MASTER_URI"]),
                                 calibration_dir=tmp_path / "calibrations")
            assert app.robot == ROBOT and app.commit_target.value == "ros"
            _wait(lambda: not app.calibrate_button.disabled, 180, "the bars to fill from the topic")
            assert app.calibrate(wait=True) is not None, app.calibrate_error
            msg = app.commit()
            assert msg.startswith(f"COMMIT to {ROBOT}: Write to"), msg
            robot_side = calib_files.load_intrinsics(robot_root / "camera_intrinsic" / f"{ROBOT}.yaml")
            truth = np.asarray(datasets.load_truth()["camera"]["K"], dtype=float)
            for ij in [(0, 0), (1, 1), (0, 2), (1, 2)]:
                assert abs(robot_side.K[ij] / truth[ij] - 1) < 0.003, (ij, robot_side.K[ij], truth[ij])
            _kill_master(env)
            _wait(lambda: app.state == "error", 30, "the UI to see the master go")
            _wait(lambda: "source lost" in app.status.value, 5, "the status line")
            kept = len(app.samples)
            assert kept >= 3 and app.result is not None
        with running_roscore(home, port) as env, \
                _started([_ros_tool("rosbag"), "play", "--quiet", "--loop", bag], env, tmp_path / "p2.log"):
            seen = app.frames_seen
            app.reconnect_button.click()
            _wait(lambda: app.frames_seen > seen + 5, 60, "frames after RECONNECT")
            assert len(app.samples) >= kept and app.state == "running"
            assert not app.loop.errors, app.loop.last_error
    finally:
        if app is not None:
            app.close()
