"""COMMIT's ``sensor_msgs/CameraInfo``, field by field, without ROS (unit tests of the message).

README: COMMIT sends the calibration to ``/<ROBOT>/camera_node/set_camera_info`` as ROS's calibrator
does. The real-ROS test (``test_ros_live.py``, slow) checks the file the camera node writes; these
check the message itself, quickly: the kit's request (``robot.commit_intrinsics`` -> JSON on the
helper's stdin) and the helper's ``CameraInfo`` (``sources/ros_helper.py``, run here with stand-ins
for ``rospy`` and ``sensor_msgs``). The calibration is chosen so that a transposed K or P, swapped
fx/fy, a dropped or reordered distortion coefficient or a swapped width/height all change a field.
"""

from __future__ import annotations

import importlib.util
import io
import json
import subprocess
import sys
import types

import cv2
import numpy as np
import pytest

from dtscal_lib import calib_files
from dtscal_lib.robot import CommitError, camera_info_dict, commit_intrinsics
from dtscal_lib.sources import live

K = np.array([[310.5, 0.0, 322.25], [0.0, 305.75, 238.5], [0.0, 0.0, 1.0]])  # fx != fy, cx != cy
D = np.array([-0.25, 0.051, 0.0011, -0.0013, 0.0])
R = cv2.Rodrigues(np.array([0.02, -0.03, 0.04]))[0]  # a rotation that is not symmetric (R != R^T)
P = np.array([[220.5, 0.0, 318.25, 1.5], [0.0, 260.75, 236.5, -2.5], [0.0, 0.0, 1.0, 0.0]])
#: the message's arrays are row-major (sensor_msgs/CameraInfo: K = [fx 0 cx 0 fy cy 0 0 1])
K_ROWS = [310.5, 0.0, 322.25, 0.0, 305.75, 238.5, 0.0, 0.0, 1.0]


@pytest.fixture()
def calib_file(tmp_path):
    calib = calib_files.IntrinsicCalibration(camera_name="/bot1/camera_node", width=640, height=480, K=K,
                                             distortion_model="plumb_bob", D=D, R=R, P=P)
    return calib_files.save_intrinsics(calib, tmp_path, "bot1")


def _check_fields(msg: dict) -> None:
    assert msg["width"] == 640 and msg["height"] == 480
    assert msg["distortion_model"] == "plumb_bob"
    assert msg["K"] == pytest.approx(K_ROWS, abs=1e-9)  # row-major: K[2] is cx, K[5] is cy (not transposed)
    assert msg["K"][2] == pytest.approx(322.25) and msg["K"][5] == pytest.approx(238.5)
    assert msg["D"] == pytest.approx(list(D), abs=1e-12) and len(msg["D"]) == 5  # k1 k2 p1 p2 k3, in order
    assert msg["R"] == pytest.approx(list(R.ravel()), abs=1e-9)
    assert msg["P"] == pytest.approx(list(P.ravel()), abs=1e-9) and len(msg["P"]) == 12  # 3x4, row-major
    assert msg["P"][3] == pytest.approx(1.5) and msg["P"][7] == pytest.approx(-2.5)


def test_the_request_the_kit_sends(calib_file, monkeypatch):
    sent = []

    def fake_helper(args, *, master=None, stdin=None, timeout=30.0):
        sent.append((args, json.loads(stdin)))
        return subprocess.CompletedProcess(args, 0, b'{"ok": true, "kind": "done", "message": "stored"}\n', b"")

    monkeypatch.setattr(live, "run_ros_helper", fake_helper)
    assert commit_intrinsics("bot1", calib_file, master_uri="http://127.0.0.1:9", timeout=2) == "stored"
    (args, msg), = sent
    assert args[:2] == ["set_camera_info", "/bot1/camera_node/set_camera_info"]
    _check_fields(msg)
    assert msg["frame_id"] == "bot1/camera_optical_frame"
    assert camera_info_dict(calib_files.load_intrinsics(calib_file), "f") == {**msg, "frame_id": "f"}


def _load_helper():
    spec = importlib.util.spec_from_file_location("dtscal_ros_helper_under_test", live.HELPER)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _fake_ros(monkeypatch, called: list, *, success: bool = True, status: str = "written") -> None:
    """Stand-ins for ``rospy`` and ``sensor_msgs`` whose service answers ``success``/``status``."""

    class CameraInfo:  # sensor_msgs.msg.CameraInfo's fields
        def __init__(self):
            self.header = types.SimpleNamespace(stamp=None, frame_id="")
            self.width = self.height = 0
            self.distortion_model = ""
            self.D, self.K, self.R, self.P = [], [0.0] * 9, [0.0] * 9, [0.0] * 12

    def service_proxy(name, srv):
        def call(info):
            called.append((name, info))
            return types.SimpleNamespace(success=success, status_message=status)
        return call

    rospy = types.ModuleType("rospy")
    rospy.init_node = lambda *a, **k: None
    rospy.wait_for_service = lambda *a, **k: None
    rospy.ServiceProxy = service_proxy
    rospy.Time = types.SimpleNamespace(now=lambda: 0)
    rospy.ROSException = rospy.ServiceException = type("ROSException", (Exception,), {})
    msg_mod, srv_mod = types.ModuleType("sensor_msgs.msg"), types.ModuleType("sensor_msgs.srv")
    msg_mod.CameraInfo, srv_mod.SetCameraInfo = CameraInfo, object
    pkg = types.ModuleType("sensor_msgs")
    pkg.msg, pkg.srv = msg_mod, srv_mod
    for name, mod in (("rospy", rospy), ("sensor_msgs", pkg), ("sensor_msgs.msg", msg_mod),
                      ("sensor_msgs.srv", srv_mod)):
        monkeypatch.setitem(sys.modules, name, mod)


def test_the_message_the_helper_builds(calib_file, monkeypatch, capsys):
    """The helper turns the JSON into a CameraInfo and calls the service with it."""
    called = []
    _fake_ros(monkeypatch, called)
    helper = _load_helper()
    monkeypatch.setattr(helper, "master_problem", lambda: None)
    request = camera_info_dict(calib_files.load_intrinsics(calib_file), frame_id="bot1/camera_optical_frame")
    monkeypatch.setattr(sys, "stdin", io.StringIO(json.dumps(request)))
    assert helper.set_camera_info("/bot1/camera_node/set_camera_info", 2.0) == 0
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1]) == {"ok": True, "kind": "done",
                                                                            "message": "written"}
    (service, info), = called
    assert service == "/bot1/camera_node/set_camera_info"
    assert info.header.frame_id == "bot1/camera_optical_frame"
    _check_fields({"width": info.width, "height": info.height, "distortion_model": info.distortion_model,
                   "K": list(info.K), "D": list(info.D), "R": list(info.R), "P": list(info.P)})


@pytest.mark.parametrize("kind, advice", [("no_service", "is the camera node of bot1 running"),
                                          ("refused", "the camera node refused"), ("no_master", "ROS_MASTER_URI")])
def test_a_refusal_is_an_error_with_advice_and_the_file_kept(calib_file, monkeypatch, kind, advice):
    before = calib_file.read_bytes()
    answer = json.dumps({"ok": False, "kind": kind, "message": f"the node said {kind}"}).encode()
    monkeypatch.setattr(live, "run_ros_helper",
                        lambda args, **k: subprocess.CompletedProcess(args, 0, answer + b"\n", b""))
    with pytest.raises(CommitError) as e:
        commit_intrinsics("bot1", calib_file, master_uri="http://127.0.0.1:9", timeout=2)
    assert f"the node said {kind}" in str(e.value) and advice in str(e.value) and "scp" in str(e.value)
    assert calib_file.read_bytes() == before


def test_the_helper_reports_the_camera_nodes_refusal(calib_file, monkeypatch, capsys):
    """ROS's sensor_msgs/SetCameraInfo.srv answers ``bool success  # True if the call succeeded`` and
    ``string status_message``: a node that could not store the calibration says ``success: false``. The helper
    process must pass that refusal on (with the node's words), not report ``ok``."""
    called = []
    _fake_ros(monkeypatch, called, success=False, status="cannot write /data/config/calibrations")
    helper = _load_helper()
    monkeypatch.setattr(helper, "master_problem", lambda: None)
    request = camera_info_dict(calib_files.load_intrinsics(calib_file), frame_id="bot1/camera_optical_frame")
    monkeypatch.setattr(sys, "stdin", io.StringIO(json.dumps(request)))
    helper.set_camera_info("/bot1/camera_node/set_camera_info", 2.0)
    said = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert len(called) == 1
    assert said == {"ok": False, "kind": "refused", "message": "cannot write /data/config/calibrations"}
