"""Duckietown's second robot, the Duckiedrone DD24: its board implies its profile, its frame calibrates.

Sources (``data/duckietown/dd24/README.md``): the DD24's intrinsic file as Duckietown ships it in
lib-dt-computer-vision (240x320, kept in ``data/duckietown/dd24/``), its board from the same library's ``boards.py``
(``CalibrationBoardDD24``: 7x5 inner corners, 17 mm squares, outer corner at x = 0.25 m, y = -0.080 m), the camera
about 5.6 cm above the board and 47 degrees down (Duckietown's real DD24 photograph, issue 21).

No real DD24 photograph is stored here, so the frame is constructed: the board drawn with numpy and seen from that
pose through the reference intrinsics scaled to the photographs' 480x640, distortion included (each pixel's ray
from ``cv2.undistortPoints`` with the file's own K and D). The kit resizes it to the file's 240x320, rectifies,
detects and fits: exit 0, and the ground under the board's corners within 1.5 mm of the construction. The same
frame judged as a Duckiebot's (``--robot-type duckiebot``) is refused: a DD24's camera is no Duckiebot's.
Agreement with Duckietown's reference ``homography.yaml`` (kept in ``data/duckietown/dd24/``; its ground frame is
the board's own): ``tests/test_dd24_reference.py``.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from drawn_ground import draw_ground
import yaml

REF = Path(__file__).resolve().parents[1] / "data" / "duckietown" / "dd24"
INTRINSICS = REF / "calibration-intrinsic-dd24.yaml"
SQUARE, OUTER_X, OUTER_Y = 0.017, 0.25, -0.080  # boards.py CalibrationBoardDD24
HEIGHT, PITCH = 0.056, np.radians(47.0)
CAMERA_AT = (0.19, -0.012)  # on the ground, behind the board, centred on it: the whole board in view


def reference_camera():
    d = yaml.safe_load(INTRINSICS.read_text())
    return (np.array(d["camera_matrix"]["data"], float).reshape(3, 3),
            np.array(d["distortion_coefficients"]["data"], float), (d["image_width"], d["image_height"]))


def ground_to_camera():
    """[r1 r2 t]: ground (x, y, 1) -> camera ray, for a camera looking forward (+x) and PITCH down."""
    z = np.array([np.cos(PITCH), 0.0, -np.sin(PITCH)])
    x = np.array([0.0, -1.0, 0.0])  # the image's right is the robot's right
    R = np.stack([x, np.cross(z, x), z])
    t = -R @ np.array([*CAMERA_AT, HEIGHT])
    return np.column_stack([R[:, 0], R[:, 1], t])


def dd24_frame(scale: int = 2, supersample: int = 2) -> np.ndarray:
    """The raw (distorted) portrait frame, 480x640 grey, of the DD24 board lying at its place."""
    K, D, size = reference_camera()

    def paint(gx, gy):
        i, j = np.floor((gx - OUTER_X) / SQUARE), np.floor((gy - OUTER_Y) / SQUARE)
        on_board = (i >= 0) & (i < 6) & (j >= 0) & (j < 8)
        paper = ((gx > OUTER_X - 0.02) & (gx < OUTER_X + 6 * SQUARE + 0.02)
                 & (np.abs(gy - OUTER_Y - 4 * SQUARE) < 0.09))
        return np.where(on_board, np.where((i + j) % 2 == 0, 235.0, 25.0), np.where(paper, 235.0, 100.0))

    return draw_ground(K, D, size, np.linalg.inv(ground_to_camera()), paint, scale=scale, supersample=supersample)


def dtscal(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "dtscal_lib.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=600, check=False)


@pytest.fixture(scope="module")
def frame_dir(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("dd24")
    frame = dd24_frame()
    assert frame.shape == (640, 480)  # portrait
    cv2.imwrite(str(d / "dd24.png"), frame)
    return d


def test_a_dd24_frame_calibrates_and_its_ground_is_right(tmp_path, frame_dir):
    p = dtscal("calibrate-extrinsics", "--source", frame_dir, "--intrinsics", INTRINSICS, "--square", "0.017",
               "--robot", "dronebot", "--out", tmp_path, "-q", "--json")
    assert p.returncode == 0, p.stderr
    assert "warning" not in p.stderr, p.stderr  # the DD24's own file is inside the DD24's range
    out = json.loads(p.stdout)
    assert out["doubts"] == []
    assert 0.05 < out["camera_pose"]["height_m"] < 0.062 and 44 < out["camera_pose"]["pitch_down_deg"] < 50
    H = np.array(yaml.safe_load((tmp_path / "camera_extrinsic" / "dronebot.yaml").read_text())["homography"])
    H = H.reshape(3, 3)
    # the board's inner corners as the rectified 240x320 camera (P = K of the file) sees them, back to the ground
    K, _, _ = reference_camera()
    j, i = np.mgrid[0:5, 0:7]
    ground = np.column_stack([OUTER_X + SQUARE * (1 + j.ravel()), OUTER_Y + SQUARE * (1 + i.ravel())])
    q = np.column_stack([ground, np.ones(len(ground))]) @ (K @ ground_to_camera()).T
    pix = q[:, :2] / q[:, 2:]
    back = np.column_stack([pix, np.ones(len(pix))]) @ H.T
    err_mm = 1000 * np.linalg.norm(back[:, :2] / back[:, 2:] - ground, axis=1)
    assert err_mm.max() < 1.5, err_mm.max()


def test_the_same_frame_as_a_duckiebots_is_refused(tmp_path, frame_dir):
    p = dtscal("calibrate-extrinsics", "--source", frame_dir, "--intrinsics", INTRINSICS, "--square", "0.017",
               "--robot-type", "duckiebot", "--robot", "dronebot", "--out", tmp_path, "-q")
    # seen as a Duckiebot's, the DD24's normal H[1][2] > 0 is Duckietown's "corrupt" homography: no fit at all
    assert p.returncode == 2, p.stderr
    assert "H[1][2]" in p.stderr and "corrupt" in p.stderr and "Traceback" not in p.stderr
    assert not (tmp_path / "camera_extrinsic").exists() or not any((tmp_path / "camera_extrinsic").iterdir())


def test_the_board_implies_the_profile():
    from dtscal_lib.boards import parse_board
    from dtscal_lib.profiles import DD24, DUCKIEBOT, profile_for

    assert profile_for(parse_board("7x5", 0.017)) is DD24 and profile_for(parse_board("7x5", 0.031)) is DUCKIEBOT
    assert profile_for(parse_board("7x5", 0.017), "duckiebot") is DUCKIEBOT
    # each profile's limits are its own rows of limits.py
    from dtscal_lib.limits import LIMITS

    assert DD24.pitch_down_deg == LIMITS["dd24_camera_pitch"].value != DUCKIEBOT.pitch_down_deg
    assert DD24.height_m == LIMITS["dd24_camera_height"].value


def test_notebook_06_tool_calibrates_the_dd24_frame(tmp_path, frame_dir):
    """The live tool drives the same session: the DD24 frame gives the same kind of answer as the command line."""
    from dtscal_lib.boards import Board
    from dtscal_lib.sources.frame import Frame
    from dtscal_lib.ui import LiveExtrinsics

    # the live tool takes frames at the intrinsic file's size (240x320); the command line resizes them itself
    frame = cv2.resize(cv2.imread(str(frame_dir / "dd24.png")), (240, 320), interpolation=cv2.INTER_AREA)
    for robot_type, written in ((None, True), ("duckiebot", False)):
        out = tmp_path / str(robot_type)
        tool = LiveExtrinsics(str(frame_dir), intrinsics=str(INTRINSICS), board=Board(7, 5, SQUARE), robot="dronebot",
                              calibration_dir=out, autostart=False, robot_type=robot_type)
        try:
            tool.loop.step(Frame(0, 0.0, frame, None, "dd24.png"))
            assert (tool.best is not None) == written, (tool.bad, tool.reason, tool.session.last_error)
            if written:
                said = tool.save()
                assert (out / "camera_extrinsic" / "dronebot.yaml").exists(), said
        finally:
            tool.close()


@pytest.mark.parametrize("fx_per_width,warned", [(0.45, True), (0.53, False), (0.644, False), (0.76, False),
                                                 (0.85, True)])
def test_dd24_files_across_the_fx_range(tmp_path, fx_per_width, warned):
    """The DD24's own file (fx 154.59 px at 240 px, 0.644 of the width) with its focal lengths set across the
    profile's range (limits.py dd24_fx_per_width: 20 % either way of it, 0.515-0.773): inside, loaded without a
    word; outside, loaded with the one-line warning (issue 31: a shifted range went unnoticed, no file fell in
    the gap). The expected side of each value is computed here from the real file, not from the kit's row."""
    import warnings

    from dtscal_lib import calib_files

    real = calib_files.load_intrinsics(REF / "calibration-intrinsic-dd24.yaml")
    assert abs(real.K[0, 0] / real.size[0] - 0.644) < 0.001
    assert warned == (not 0.8 * 0.644 <= fx_per_width <= 1.2 * 0.644)
    K = real.K.copy()
    K[0, 0] = K[1, 1] = fx_per_width * real.size[0]
    P = real.P.copy()
    P[0, 0] = P[1, 1] = K[0, 0]
    scaled = calib_files.IntrinsicCalibration(real.camera_name, real.width, real.height, K, real.distortion_model,
                                              real.D, real.R, P)
    path = calib_files.save_intrinsics(scaled, tmp_path, "dd24bot")
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        calib_files.load_intrinsics(path)
    words = [str(w.message) for w in seen if issubclass(w.category, calib_files.CalibrationFileWarning)]
    assert bool([w for w in words if "outside every real dd24's camera" in w]) == warned, words
