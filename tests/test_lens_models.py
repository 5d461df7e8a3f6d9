"""ROS's other lens models: ``rational_polynomial`` (k1-k6, p1, p2) and ``equidistant`` (fisheye) (issue 25).

Sources: ROS's camera_calibration calibrator.py (``cv2.calibrateCamera`` with ``CALIB_RATIONAL_MODEL``, D =
``dist_coeffs.flat[:8]``; ``cv2.fisheye.calibrate``, D of 4; the fisheye P is K with fx, fy / (1 + alpha)) and
image_common's camera_calibration_parsers parse_yml.cpp (the YAML layout: ``rows``, ``cols``, ``data`` as a
flow sequence; D has ``cols`` = its length). Expectations are OpenCV's own functions on the same input, never
the kit's: projection (``projectPoints``, ``fisheye.projectPoints``), undistortion (``undistortPointsIter``,
``fisheye.undistortPoints``), maps (``initUndistortRectifyMap``, ``fisheye.initUndistortRectifyMap``) and the
calibration itself on the kit's corners of OpenCV's real left photographs (acceptance: focal lengths equal to
0.1 %).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from dtscal_lib import pipeline, robot
from dtscal_lib.boards import parse_board
from dtscal_lib.calib_files import IntrinsicCalibration, load_intrinsics, save_intrinsics
from dtscal_lib.camera import CameraModel, intrinsic_matrix, project_points, undistort_pixels
from dtscal_lib.errors import CalibrationFileError
from dtscal_lib.ground import distorted_pixel_to_ground

REAL = Path(__file__).resolve().parents[1] / "data" / "real" / "opencv-samples"
K = intrinsic_matrix(300.0, 305.0, 322.0, 238.0)
RATIONAL = np.array([-0.3, 0.1, 0.001, -0.002, 0.01, 0.05, -0.02, 0.01])
FISHEYE = np.array([0.05, -0.02, 0.01, -0.003])
SIZE = (640, 480)

# a file exactly as camera_calibration_parsers' writeCalibrationYml (yaml-cpp's emitter) writes it
ROS_RATIONAL = """image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [300.5, 0, 322.25, 0, 305.125, 238.5, 0, 0, 1]
distortion_model: rational_polynomial
distortion_coefficients:
  rows: 1
  cols: 8
  data: [-0.3, 0.1, 0.001, -0.002, 0.01, 0.05, -0.02, 0.01]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [250.25, 0, 320.5, 0, 0, 260.75, 240.25, 0, 0, 0, 1, 0]"""
ROS_FISHEYE = ROS_RATIONAL.replace("rational_polynomial", "equidistant").replace(
    "  cols: 8\n  data: [-0.3, 0.1, 0.001, -0.002, 0.01, 0.05, -0.02, 0.01]",
    "  cols: 4\n  data: [0.05, -0.02, 0.01, -0.003]")


def _points(n=300, seed=1):
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(-0.5, 0.5, (n, 2)), np.ones(n)])


RV, TV = np.array([0.1, -0.2, 0.05]), np.array([0.01, 0.02, 0.5])


# --------------------------------------------------------------------------- the models against OpenCV
def test_projection_and_undistortion_equal_opencv():
    X = _points()
    q = project_points(X, RV, TV, K, RATIONAL, model="rational_polynomial")
    assert np.abs(q - cv2.projectPoints(X, RV, TV, K, RATIONAL)[0].reshape(-1, 2)).max() < 1e-9
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-15)
    want = cv2.undistortPointsIter(q.reshape(-1, 1, 2), K, RATIONAL, None, None, crit).reshape(-1, 2)
    assert np.abs(undistort_pixels(q, K, RATIONAL, model="rational_polynomial") - want).max() < 1e-9

    q = project_points(X, RV, TV, K, FISHEYE, model="equidistant")
    assert np.abs(q - cv2.fisheye.projectPoints(X.reshape(-1, 1, 3), RV, TV, K, FISHEYE)[0].reshape(-1, 2)).max() < 1e-9
    want = cv2.fisheye.undistortPoints(q.reshape(-1, 1, 2), K, FISHEYE).reshape(-1, 2)
    assert np.abs(undistort_pixels(q, K, FISHEYE, model="equidistant") - want).max() < 1e-9


@pytest.mark.parametrize("model,dist", [("rational_polynomial", RATIONAL), ("equidistant", FISHEYE)])
def test_rectification_maps_equal_opencv(model, dist):
    cam = CameraModel(K, dist, SIZE, model)
    if model == "equidistant":  # ROS's calibrator: P = K, fx and fy divided by 1 + alpha (alpha = 0)
        assert np.array_equal(cam.rectified_K, K)
        want = cv2.fisheye.initUndistortRectifyMap(K, dist, np.eye(3), cam.rectified_K, SIZE, cv2.CV_32FC1)
    else:
        newK = cv2.getOptimalNewCameraMatrix(K, dist, SIZE, 0.0, SIZE)[0]
        assert np.allclose(cam.rectified_K, newK, rtol=0, atol=1e-9)
        want = cv2.initUndistortRectifyMap(K, dist, np.eye(3), newK, SIZE, cv2.CV_32FC1)
    got = cam.rectification_maps()
    for g, w in zip(got, want):  # float32 maps: a few ulp of a 640-px coordinate
        assert np.abs(g - w).max() < 1e-3
    for g, w in zip(cam.opencv_maps(), want):
        assert np.array_equal(g, w)


@pytest.mark.parametrize("model,dist", [("rational_polynomial", RATIONAL), ("equidistant", FISHEYE)])
def test_ground_projection_undistorts_through_the_model(model, dist):
    cam = CameraModel(K, dist, SIZE, model)
    H = np.array([[-1e-4, 2e-3, 0.3], [-2e-3, 1e-5, 0.6], [1e-6, 8e-3, 1.0]])
    uv = np.array([[100.0, 400.0], [320.0, 300.0], [600.0, 420.0]])
    P = cam.rectified_K
    if model == "equidistant":
        rect = cv2.fisheye.undistortPoints(uv.reshape(-1, 1, 2), K, dist, P=P).reshape(-1, 2)
    else:
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-15)
        rect = cv2.undistortPointsIter(uv.reshape(-1, 1, 2), K, dist, None, P, crit).reshape(-1, 2)
    h = np.column_stack([rect, np.ones(3)]) @ H.T
    assert np.allclose(distorted_pixel_to_ground(cam, H, uv), h[:, :2] / h[:, 2:], rtol=0, atol=1e-9)


# --------------------------------------------------------------------------- files, as ROS writes them
@pytest.mark.parametrize("text,model,n", [(ROS_RATIONAL, "rational_polynomial", 8), (ROS_FISHEYE, "equidistant", 4)])
def test_a_file_in_ros_layout_reads_and_round_trips_byte_for_byte(tmp_path, text, model, n):
    p = tmp_path / "camera_intrinsic" / "ros.yaml"
    p.parent.mkdir()
    p.write_text(text + "\n")
    calib = load_intrinsics(p)
    assert calib.distortion_model == model and calib.D.shape == (n,)
    want = RATIONAL if n == 8 else FISHEYE
    assert np.array_equal(calib.D, want)  # every coefficient, k4..k6 included
    out = save_intrinsics(calib, tmp_path, "bot")
    first = out.read_bytes()
    assert first.decode() == text + "\n"  # ROS's own text, unchanged
    again = save_intrinsics(load_intrinsics(out), tmp_path, "bot2")
    assert again.read_bytes() == first
    assert f"  cols: {n}\n" in first.decode()


def test_a_wrong_number_of_coefficients_is_refused_with_the_model_s_names(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text(ROS_FISHEYE.replace("cols: 4\n  data: [0.05, -0.02, 0.01, -0.003]",
                                     "cols: 5\n  data: [0.05, -0.02, 0.01, -0.003, 0]"))
    with pytest.raises(CalibrationFileError, match=r"equidistant needs 4 \[k1, k2, k3, k4\]"):
        load_intrinsics(p)


@pytest.mark.parametrize("text,n", [(ROS_RATIONAL, 8), (ROS_FISHEYE, 4)])
def test_commit_sends_d_of_the_model_s_length(tmp_path, text, n):
    p = tmp_path / "c.yaml"
    p.write_text(text)
    info = robot.camera_info_dict(load_intrinsics(p))
    assert len(info["D"]) == n and info["distortion_model"] in ("rational_polynomial", "equidistant")


# --------------------------------------------------------------------------- calibration: OpenCV's, on the same corners
@pytest.fixture(scope="module")
def left_runs():
    board = parse_board("9x6", 0.03)
    return {m: pipeline.calibrate_intrinsics(REAL / "left", board=board, model=m, out_dir=None)
            for m in ("rational_polynomial", "equidistant")}


def test_rational_polynomial_equals_opencv_calibrate_camera(left_runs):
    r = left_runs["rational_polynomial"].result
    obj = [np.column_stack([o[:, :2], np.zeros(len(o))]).astype(np.float32) for o in r.object_points]
    img = [p.reshape(-1, 1, 2).astype(np.float32) for p in r.image_points]
    rms, Kc, dc, _, _ = cv2.calibrateCamera(obj, img, r.image_size, None, None, flags=cv2.CALIB_RATIONAL_MODEL)
    assert r.model == "rational_polynomial" and r.dist.shape == (8,)
    assert r.K[0, 0] == pytest.approx(Kc[0, 0], rel=1e-3) and r.K[1, 1] == pytest.approx(Kc[1, 1], rel=1e-3)
    assert r.rms == pytest.approx(rms, rel=1e-3)
    cal = IntrinsicCalibration.from_camera(r.camera(), "left")
    assert cal.distortion_model == "rational_polynomial" and cal.D.shape == (8,)


def test_equidistant_equals_opencv_fisheye_calibrate(left_runs):
    r = left_runs["equidistant"].result
    obj = [np.column_stack([o[:, :2], np.zeros(len(o))]).reshape(-1, 1, 3) for o in r.object_points]
    img = [p.reshape(-1, 1, 2).astype(np.float64) for p in r.image_points]
    flags = cv2.fisheye.CALIB_RECOMPUTE_EXTRINSIC | cv2.fisheye.CALIB_FIX_SKEW
    rms, Kc, dc, _, _ = cv2.fisheye.calibrate(obj, img, r.image_size, None, None, flags=flags)
    assert r.model == "equidistant" and r.dist.shape == (4,)
    assert r.K[0, 0] == pytest.approx(Kc[0, 0], rel=1e-3) and r.K[1, 1] == pytest.approx(Kc[1, 1], rel=1e-3)
    assert r.rms == pytest.approx(rms, rel=1e-3)
    cal = IntrinsicCalibration.from_camera(r.camera(), "left")
    assert cal.to_dict()["distortion_coefficients"]["cols"] == 4


def test_the_fisheye_model_recovers_a_fisheye_camera():
    """Views drawn with cv2.fisheye.projectPoints from a known camera: the kit's calibration returns it."""
    board = parse_board("9x6", 0.03)
    obj = board.object_points()
    rng = np.random.default_rng(5)
    views = []
    for _ in range(15):
        rv = rng.normal(0, 0.35, 3)
        tv = np.array([-0.12 + rng.normal(0, 0.05), -0.08 + rng.normal(0, 0.05), rng.uniform(0.25, 0.45)])
        q = cv2.fisheye.projectPoints(np.column_stack([obj[:, :2], np.zeros(len(obj))]).reshape(-1, 1, 3), rv, tv,
                                      K, FISHEYE)[0].reshape(-1, 2)
        if np.all((q > 10) & (q < np.array(SIZE) - 10)):
            views.append(q)
    from dtscal_lib.calibration import calibrate

    r = calibrate([obj] * len(views), views, SIZE, model="equidistant")
    assert len(views) >= 6
    assert np.allclose(r.K, K, rtol=1e-6, atol=1e-6) and np.allclose(r.dist, FISHEYE, atol=1e-6)
