"""Tests of dtscal_lib.ground: ground homography, pixel <-> ground, extrinsic calibration, views."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dtscal_lib import duckietown as dt
from dtscal_lib import synth
from dtscal_lib.boards import DUCKIETOWN_BOARD, GROUND_NEAR_ROW_X, Board, ground_points
from dtscal_lib.camera import CameraModel
from dtscal_lib.errors import CalibrationError, DtscalError
from dtscal_lib.ground import (
    ExtrinsicResult,
    apply_homography,
    birdseye_view,
    extrinsics_from_image,
    distorted_pixel_to_ground,
    draw_ground_grid,
    estimate_ground_homography,
    ground_to_pixel,
    pixel_to_ground,
)


# --------------------------------------------------------------------------- synthetic scenes
def default_camera() -> CameraModel:
    return CameraModel(dt.default_K(), dt.default_dist(), dt.IMAGE_SIZE, P=dt.default_P())


def pose_homography(Kp: np.ndarray, height: float, pitch_deg: float, yaw_deg: float = 0.0,
                    cam_x: float = 0.06, cam_y: float = 0.0) -> np.ndarray:
    """Ground -> rectified pixel -> inverted: the rectified-pixel -> ground H of a posed camera.

    Camera at (cam_x, cam_y, height) in the robot frame, looking forward, pitched down by
    ``pitch_deg`` and turned left by ``yaw_deg``; camera axes x right, y down, z forward.
    """
    p, y = math.radians(pitch_deg), math.radians(yaw_deg)
    z_c = np.array([math.cos(p), 0.0, -math.sin(p)])
    x_c = np.array([0.0, -1.0, 0.0])
    y_c = np.cross(z_c, x_c)
    Rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    R = np.stack([Rz @ x_c, Rz @ y_c, Rz @ z_c])  # rows: camera axes in the robot frame
    C = np.array([cam_x, cam_y, height])
    G = Kp @ np.column_stack([R[:, 0], R[:, 1], -R @ C])  # [x, y, 1] on the ground -> pixel
    H = np.linalg.inv(G)
    return H / H[2, 2]


_CASTERS: dict = {}


def render_board_frame(camera: CameraModel, H: np.ndarray, board: Board = DUCKIETOWN_BOARD) -> np.ndarray:
    """The raw (distorted) frame a camera with ground homography H sees of the board on the floor.

    The kit's ray caster (:class:`dtscal_lib.synth.Renderer`, 2x2 sub-pixels) meets the ground
    with every sub-pixel's ray: rectified pixel ``Kp [x, y, 1]`` -> ground ``H Kp [x, y, 1]``.
    The floor is grey (120), the paper white (235), the board's dark squares black (20; the corner square
    nearest the robot on its right is white, as on Duckietown's printed A3 pattern, duckietown.md), what lies
    above the horizon 90; the sub-pixels are area-averaged to pixels.
    """
    key = id(camera)
    if key not in _CASTERS:
        _CASTERS[key] = (camera, synth.make_renderer(camera, 2))  # keep the camera: its id stays its own
    caster = _CASTERS[key][1]
    w, h = camera.size
    G = H @ camera.rectified_K                          # normalized ray (x, y, 1) -> ground, up to scale
    G = G * np.sign(H[2] @ [w / 2, h - 1, 1.0])         # w > 0 below the horizon (the bottom centre is)
    M = np.linalg.inv(G)                                # ground (X, Y, 1) -> ray: the plane's [r1 r2 t]
    X, Y, front = caster.plane_coords(np.column_stack([M[:, 0], M[:, 1], np.cross(M[:, 0], M[:, 1])]), M[:, 2])
    s = board.square
    x_lo = GROUND_NEAR_ROW_X - s                       # near edge of the squares
    y_lo = -(board.cols - 1) * s / 2 - s               # right edge of the squares
    i = np.floor((X - x_lo) / s).astype(int)
    j = np.floor((Y - y_lo) / s).astype(int)
    on_board = (i >= 0) & (i <= board.rows) & (j >= 0) & (j <= board.cols)
    m = 0.02
    paper = ((X > x_lo - m) & (X < x_lo + (board.rows + 1) * s + m)
             & (Y > y_lo - m) & (Y < y_lo + (board.cols + 1) * s + m))
    grey = np.full(X.shape, 120.0, np.float32)
    grey[paper] = 235.0
    grey[on_board & ((i + j) % 2 == 1)] = 20.0  # Duckietown's print: the near-right corner square white
    grey[~front] = 90.0
    grey = np.rint(caster.downsample(grey)).astype(np.uint8)
    assert grey.shape == (h, w)
    return cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)


@pytest.fixture(scope="module")
def camera() -> CameraModel:
    return default_camera()


@pytest.fixture(scope="module")
def default_frame(camera) -> np.ndarray:
    return render_board_frame(camera, dt.default_H())


def _corner_error_mm(H_est: np.ndarray, H_true: np.ndarray, board: Board = DUCKIETOWN_BOARD) -> np.ndarray:
    truth = ground_points(board)
    seen = ground_to_pixel(H_true, truth)            # where the corners truly are in the rectified image
    return 1000 * np.linalg.norm(pixel_to_ground(H_est, seen) - truth, axis=1)


# --------------------------------------------------------------------------- the default homography
def test_default_homography_sanity_check():
    H = dt.default_H()
    np.testing.assert_allclose(pixel_to_ground(H, [320, 479])[0], [0.117, 0.004], atol=1e-3)
    assert pixel_to_ground(H, [[320, 240]])[0, 0] == pytest.approx(0.289, abs=1e-3)


def test_ground_to_pixel_inverts():
    H = dt.default_H()
    uv = np.array([[320.0, 479.0], [10.0, 300.0], [630.0, 470.0]])
    np.testing.assert_allclose(ground_to_pixel(H, pixel_to_ground(H, uv)), uv, atol=1e-9)


def test_apply_homography_refuses_horizon_points():
    H = dt.default_H()
    # a pixel on the horizon line: H[2] . [u, v, 1] = 0
    u = 320.0
    v = -(H[2, 0] * u + H[2, 2]) / H[2, 1]
    with pytest.raises(DtscalError, match="infinity.*horizon"):
        pixel_to_ground(H, [u, v])


@pytest.mark.parametrize("bad,pattern", [(np.zeros((3, 3)), "shape"), (np.full((2, 2), np.nan), "NaN")])
def test_apply_homography_checks_points(bad, pattern):
    with pytest.raises(DtscalError, match=pattern):
        apply_homography(dt.default_H(), bad)


def test_apply_homography_checks_H():
    with pytest.raises(DtscalError, match="3x3"):
        apply_homography(np.eye(2), [[1.0, 2.0]])
    with pytest.raises(DtscalError, match="singular"):
        ground_to_pixel(np.zeros((3, 3)), [[1.0, 2.0]])


# --------------------------------------------------------------------------- estimation
@pytest.mark.parametrize("method", ["ransac", "lsq"])
def test_estimate_recovers_known_H(method):
    H = pose_homography(dt.default_P()[:, :3], 0.10, 20, 5)
    truth = ground_points()
    px = ground_to_pixel(H, truth)
    H_est = estimate_ground_homography(px, truth, method=method)
    assert H_est[2, 2] == 1.0
    np.testing.assert_allclose(apply_homography(H_est, px), truth, atol=1e-7)
    # the whole lower image maps like the true H (to 0.01 mm)
    u, v = np.meshgrid(np.linspace(0, 639, 9), np.linspace(300, 479, 5))
    grid = np.column_stack([u.ravel(), v.ravel()])
    np.testing.assert_allclose(pixel_to_ground(H_est, grid), pixel_to_ground(H, grid), atol=1e-5)


def test_ransac_rejects_a_bad_corner_lsq_does_not():
    H = dt.default_H()
    truth = ground_points()
    px = ground_to_pixel(H, truth)
    px[7] += [9.0, -6.0]  # one badly detected corner
    err_r = np.abs(pixel_to_ground(estimate_ground_homography(px, truth), ground_to_pixel(H, truth)) - truth).max()
    err_l = np.abs(pixel_to_ground(estimate_ground_homography(px, truth, method="lsq"),
                                   ground_to_pixel(H, truth)) - truth).max()
    assert err_r < 1e-6
    assert err_l > 1e-3


@settings(max_examples=40, deadline=None)
@given(height=st.floats(0.06, 0.2), pitch=st.floats(5, 40), yaw=st.floats(-15, 15),
       cam_y=st.floats(-0.03, 0.03))
def test_estimate_apply_round_trip_property(height, pitch, yaw, cam_y):
    H = pose_homography(dt.default_P()[:, :3], height, pitch, yaw, cam_y=cam_y)
    truth = ground_points()
    px = ground_to_pixel(H, truth)
    H_est = estimate_ground_homography(px, truth, method="lsq")
    np.testing.assert_allclose(apply_homography(H_est, px), truth, atol=1e-7)
    np.testing.assert_allclose(ground_to_pixel(H_est, truth), px, atol=1e-4)


@pytest.mark.parametrize("px,gr,pattern", [
    (np.zeros((3, 2)), np.zeros((3, 2)), "at least 4"),
    (np.zeros((5, 2)), np.zeros((4, 2)), "pair up"),
    (np.column_stack([np.arange(6.0), np.arange(6.0)]), np.column_stack([np.arange(6.0), 2 * np.arange(6.0)]),
     "collinear"),
])
def test_estimate_degenerate(px, gr, pattern):
    with pytest.raises(CalibrationError, match=pattern):
        estimate_ground_homography(px, gr)


def test_estimate_bad_method():
    truth = ground_points()
    with pytest.raises(CalibrationError, match="method"):
        estimate_ground_homography(ground_to_pixel(dt.default_H(), truth), truth, method="magic")


# --------------------------------------------------------------------------- distorted pixels
def test_distorted_pixel_to_ground_matches_opencv(camera):
    uv = np.array([[320.0, 479.0], [50.0, 400.0], [600.0, 300.0]])
    rect = cv2.undistortPointsIter(uv.reshape(-1, 1, 2), camera.K, camera.dist, np.eye(3), camera.P,
                                   (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12))
    expected = pixel_to_ground(dt.default_H(), rect.reshape(-1, 2))
    np.testing.assert_allclose(distorted_pixel_to_ground(camera, dt.default_H(), uv), expected, atol=1e-5)


# --------------------------------------------------------------------------- the procedure
def test_calibrate_extrinsics_default_scene(camera, default_frame):
    res = extrinsics_from_image(default_frame, camera)
    assert isinstance(res, ExtrinsicResult)
    assert res.corners_rectified.shape == (35, 2) and res.ground.shape == (35, 2)
    np.testing.assert_array_equal(res.ground, ground_points())
    assert _corner_error_mm(res.H, dt.default_H()).max() < 3.0
    assert res.residual_mm.shape == (35,) and res.residual_mm.max() < 3.0
    assert not dt.homography_is_corrupt(res.H)
    assert res.rectified.shape == default_frame.shape
    assert res.image_center_ground[0] == pytest.approx(0.289, abs=0.005)
    d = res.to_dict()
    assert len(d["homography"]) == 9 and d["n_corners"] == 35 and d["residual_mm_max"] < 3.0
    # first corner is the near-right one: largest v and u in the rectified image
    assert res.corners_rectified[0, 1] > res.corners_rectified[-1, 1]
    assert res.corners_rectified[0, 0] > res.corners_rectified[6, 0]


@pytest.mark.parametrize("height,pitch,yaw", [(0.11, 25.0, 4.0), (0.09, 15.0, -6.0)])
def test_calibrate_extrinsics_posed_cameras(camera, height, pitch, yaw):
    H_true = pose_homography(camera.rectified_K, height, pitch, yaw)
    frame = render_board_frame(camera, H_true)
    res = extrinsics_from_image(frame, camera)
    err = _corner_error_mm(res.H, H_true)
    assert err.max() < 3.0, err.max()


def test_calibrate_extrinsics_resizes_other_widths(camera, default_frame):
    big = cv2.resize(default_frame, (1280, 960), interpolation=cv2.INTER_CUBIC)
    res = extrinsics_from_image(big, camera)
    assert res.rectified.shape[:2] == (480, 640)
    assert _corner_error_mm(res.H, dt.default_H()).max() < 3.0
    grey_small = cv2.resize(cv2.cvtColor(default_frame, cv2.COLOR_BGR2GRAY), (960, 720))
    res2 = extrinsics_from_image(grey_small, camera)
    assert _corner_error_mm(res2.H, dt.default_H()).max() < 3.0


def test_calibrate_extrinsics_wrong_aspect(camera, default_frame):
    with pytest.raises(CalibrationError, match="calibrated at 640x480"):
        extrinsics_from_image(cv2.resize(default_frame, (640, 360)), camera)


def test_calibrate_extrinsics_no_board(camera):
    blank = np.full((480, 640, 3), 128, np.uint8)
    with pytest.raises(CalibrationError, match="place the robot on the board"):
        extrinsics_from_image(blank, camera)


def test_calibrate_extrinsics_board_at_border(camera):
    # robot turned 25 degrees: the board's left end reaches the rectified image's right edge (with the printed
    # pattern's colours the left end's outer squares are black-white from near to far; turned 29 degrees, the
    # edge cuts the black one and OpenCV's detector no longer sees the board at all)
    frame = render_board_frame(camera, pose_homography(camera.rectified_K, 0.10, 20, 25))
    with pytest.raises(CalibrationError, match="within 8 px of the rectified image's edge"):
        extrinsics_from_image(frame, camera)


def test_calibrate_extrinsics_rejects_bad_input(camera):
    with pytest.raises(CalibrationError, match="uint8"):
        extrinsics_from_image(np.zeros((480, 640), np.float32), camera)
    with pytest.raises(CalibrationError, match="non-empty"):
        extrinsics_from_image(np.zeros((0, 0), np.uint8), camera)
    with pytest.raises(CalibrationError, match="CameraModel"):
        extrinsics_from_image(np.zeros((480, 640), np.uint8), "camera")


# --------------------------------------------------------------------------- views
def test_birdseye_view_geometry(camera, default_frame):
    rect = camera.rectification_maps()
    rectified = cv2.remap(default_frame, *rect, cv2.INTER_LINEAR)
    ppm = 1000
    view = birdseye_view(rectified, dt.default_H(), x_range=(0.15, 0.40), y_range=(-0.15, 0.15), px_per_m=ppm)
    assert view.shape == (250, 300, 3)
    grey = view[:, :, 0].astype(int)

    def at(x, y):  # pixel of ground point (x, y)
        return grey[int((0.40 - x) * ppm), int((0.15 - y) * ppm)]

    s = DUCKIETOWN_BOARD.square
    # squares of the board (Duckietown's printed A3 pattern, duckietown.md): the corner square nearest the
    # robot on its right is white, its left neighbour dark
    x_sq = GROUND_NEAR_ROW_X - s / 2
    y_right = -0.093 - s / 2
    assert at(x_sq, y_right) > 180
    assert at(x_sq, y_right + s) < 80
    assert at(x_sq + s, y_right + s) > 180
    # not mirrored: the near-left square is black, the far-left white, the far-right black
    assert at(x_sq, 0.093 + s / 2) < 80
    assert at(x_sq + 5 * s, 0.093 + s / 2) > 180
    assert at(x_sq + 5 * s, y_right) < 80
    # beyond the paper: the grey floor
    assert 100 < at(0.39, 0.0) < 140


def test_birdseye_view_bad_ranges():
    with pytest.raises(DtscalError, match="min < max"):
        birdseye_view(np.zeros((480, 640), np.uint8), dt.default_H(), x_range=(0.5, 0.1))


def test_draw_ground_grid(camera, default_frame):
    rectified = cv2.remap(default_frame, *camera.rectification_maps(), cv2.INTER_LINEAR)
    grey = cv2.cvtColor(rectified, cv2.COLOR_BGR2GRAY)
    out = draw_ground_grid(grey, dt.default_H(), spacing=0.05, color=(0, 255, 0), labels=False)
    assert out.shape == (480, 640, 3) and out.dtype == np.uint8
    green = (out[:, :, 1] > 200) & (out[:, :, 0] < 100)
    # the line x = 0.20 m, y = 0 lies where H^-1 puts it
    u, v = ground_to_pixel(dt.default_H(), [0.20, 0.0])[0]
    assert green[int(round(v)) - 1: int(round(v)) + 2, int(round(u)) - 1: int(round(u)) + 2].any()
    # nothing drawn above the horizon (the top rows see no ground)
    assert not green[:100].any()
    assert np.array_equal(grey, cv2.cvtColor(rectified, cv2.COLOR_BGR2GRAY))  # input untouched
    with pytest.raises(DtscalError, match="spacing"):
        draw_ground_grid(grey, dt.default_H(), spacing=0)
