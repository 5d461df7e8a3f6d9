"""Frames of a pattern lying on the ground, drawn with numpy through a real camera's intrinsics: the test's
own picture of a scene, independent of the kit's renderer (``dtscal_lib.synth``).

Each pixel (supersampled) is undistorted with OpenCV, its ray met with the ground plane through
``ground_from_ray`` (a 3x3 map from normalized camera rays to homogeneous ground points), and the ground
point coloured by ``paint(gx, gy)`` (grey levels); pixels whose ray does not meet the ground ahead are the
background. A little seeded sensor noise is added, as a camera has.

Also the two documented scenes the tests draw: Duckietown's printed A3 board seen through its default homography
(``printed_board_frame``, ``intrinsic_file``) and the DD24 board at Duckietown's reference pose
(``reference_frame``), shared by ``test_board_layout``, ``test_dd24_reference`` and ``test_fleet_mounts``.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import yaml

BACKGROUND = 100.0


def draw_ground(K, D, size, ground_from_ray, paint, *, scale: int = 2, supersample: int = 2,
                seed: int = 24) -> np.ndarray:
    """The raw (distorted) grey frame of ``size`` = (w, h) times ``scale`` of the painted ground."""
    w, h = size
    Ks = np.asarray(K, dtype=np.float64) * scale
    Ks[2, 2] = 1.0
    W, H, s = w * scale, h * scale, supersample
    v, u = np.mgrid[0:H * s, 0:W * s]
    pix = np.column_stack([(u.ravel() + 0.5) / s - 0.5, (v.ravel() + 0.5) / s - 0.5]).astype(np.float64)
    rays = cv2.undistortPoints(pix.reshape(-1, 1, 2), Ks, np.asarray(D, dtype=np.float64)).reshape(-1, 2)
    g = np.column_stack([rays, np.ones(len(rays))]) @ np.asarray(ground_from_ray, dtype=np.float64).T
    front = g[:, 2] > 0  # the ray meets the ground ahead of the camera
    with np.errstate(divide="ignore", invalid="ignore"):
        grey = paint(g[:, 0] / g[:, 2], g[:, 1] / g[:, 2])
    grey = np.where(front, grey, BACKGROUND).reshape(H, s, W, s).mean(axis=(1, 3))
    grey += np.random.default_rng(seed).normal(0.0, 2.0, grey.shape)
    return np.clip(np.rint(grey), 0, 255).astype(np.uint8)


# ------------------------------------------------ the Duckiebot's printed A3 board (tests/test_board_layout.py)
# Duckietown's shipped files, value for value (duckietown.md)
DEFAULT_P = np.array([[210.1107940673828, 0, 327.2577820024981], [0, 253.8408660888672, 239.9969353923052],
                      [0, 0, 1]])
DEFAULT_H = np.array([-4.89775e-05, -0.0002150858, -0.1818273, 0.00099274, 1.202336e-06, -0.3280241,
                      -0.0004281805, -0.007185673, 1]).reshape(3, 3)
DUCKIEBOT_SQUARE, OUTER_X, OUTER_Y = 0.031, 0.160, -0.124  # boards.py CalibrationBoard8by6 (x_offset, y_offset)
ALONG, ACROSS = 6, 8  # squares away from the robot (x), across its view (y)


def printed_board_frame(width: int = 640, height: int = 480, supersample: int = 4) -> np.ndarray:
    """The rectified camera's view of the printed sheet lying at its place: grey (h, w) uint8."""
    s = supersample
    v, u = np.mgrid[0:height * s, 0:width * s]
    pix = np.stack([(u + 0.5) / s - 0.5, (v + 0.5) / s - 0.5, np.ones(u.shape)], axis=-1)
    g = pix @ DEFAULT_H.T
    x, y = g[..., 0] / g[..., 2], g[..., 1] / g[..., 2]
    i = np.floor((x - OUTER_X) / DUCKIEBOT_SQUARE)  # 0 = the row of squares nearest the robot
    j = np.floor((y - OUTER_Y) / DUCKIEBOT_SQUARE)  # 0 = the column on the robot's right
    on_board = (i >= 0) & (i < ALONG) & (j >= 0) & (j < ACROSS)
    white = (i + j) % 2 == 0  # (0, 0), the near-right corner square, is white
    on_paper = (np.abs(x - (OUTER_X + ALONG * DUCKIEBOT_SQUARE / 2)) < 0.297 / 2) & (np.abs(y) < 0.420 / 2)  # A3 sheet
    grey = np.where(on_board, np.where(white, 235.0, 25.0), np.where(on_paper, 235.0, 110.0))
    below = np.sign(g[..., 2]) == np.sign((DEFAULT_H @ [width / 2, height - 1.0, 1.0])[2])
    grey = np.where(below, grey, 110.0)  # above the horizon: the room
    grey = grey.reshape(height, s, width, s).mean(axis=(1, 3))
    noise = np.random.default_rng(21).normal(0.0, 2.0, grey.shape)
    return np.clip(np.rint(grey + noise), 0, 255).astype(np.uint8)


def intrinsic_file(path: Path) -> Path:
    """A camera without distortion whose K is the default file's rectified P: its frames are rectified."""
    K = DEFAULT_P.ravel().tolist()
    doc = {"image_width": 640, "image_height": 480, "camera_name": "/layoutbot/camera_node",
           "camera_matrix": {"rows": 3, "cols": 3, "data": K}, "distortion_model": "plumb_bob",
           "distortion_coefficients": {"rows": 1, "cols": 5, "data": [0.0] * 5},
           "rectification_matrix": {"rows": 3, "cols": 3, "data": [1, 0, 0, 0, 1, 0, 0, 0, 1]},
           "projection_matrix": {"rows": 3, "cols": 4, "data": [*K[0:3], 0, *K[3:6], 0, *K[6:9], 0]}}
    path.write_text(yaml.safe_dump(doc))
    return path


# ------------------------------------------------ Duckietown's DD24 reference (tests/test_dd24_reference.py)
REF = Path(__file__).resolve().parents[1] / "data" / "duckietown" / "dd24"
HOMOGRAPHY, INTRINSICS = REF / "homography.yaml", REF / "calibration-intrinsic-dd24.yaml"
DD24_SQUARE, DD24_COLS, DD24_ROWS = 0.017, 7, 5  # boards.py CalibrationBoardDD24: inner corners 7 x 5


def reference():
    F = np.array(yaml.safe_load(HOMOGRAPHY.read_text())["homography"], float).reshape(3, 3)
    d = yaml.safe_load(INTRINSICS.read_text())
    K = np.array(d["camera_matrix"]["data"], float).reshape(3, 3)
    return F, K, np.array(d["distortion_coefficients"]["data"], float), (d["image_width"], d["image_height"])


def board_to_camera(F):
    """[r1 r2 t] of the reference: ground (board frame) -> normalized camera ray, scaled so |r1| = 1, t_z > 0."""
    M = np.linalg.inv(F)
    M = M / np.linalg.norm(M[:, 0])
    return -M if M[2, 2] < 0 else M


def reference_frame(scale: int = 2, supersample: int = 2) -> np.ndarray:
    """The raw portrait frame (480x640 grey) of the DD24 board seen from the reference file's camera pose."""
    F, K, D, size = reference()

    def paint(gx, gy):
        a, c = np.floor(gx / DD24_SQUARE) + 1, np.floor(gy / DD24_SQUARE) + 1  # squares around the inner-corner grid
        on_board = (a >= 0) & (a < DD24_COLS + 1) & (c >= 0) & (c < DD24_ROWS + 1)
        margin = DD24_SQUARE + 0.015
        paper = ((gx > -margin) & (gx < DD24_COLS * DD24_SQUARE + 0.015) & (gy > -margin)
                 & (gy < DD24_ROWS * DD24_SQUARE + 0.015))
        return np.where(on_board, np.where((a + c) % 2 == 0, 235.0, 25.0), np.where(paper, 235.0, 100.0))

    return draw_ground(K, D, size, np.linalg.inv(board_to_camera(F)), paint, scale=scale, supersample=supersample)
