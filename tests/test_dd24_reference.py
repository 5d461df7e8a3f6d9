"""Duckietown's DD24 reference homography, read as Duckietown wrote it, and the kit's homography beside it.

Sources (``data/duckietown/dd24/README.md``; ``docs/robot.md``): lib-dt-computer-vision's
``assets/extrinsics/dd24/real-world/scenario0/homography.yaml`` and ``calibration-intrinsic-dd24.yaml``
(240x320), written on 2024-08-18 by its ``notebooks/22-extrinsics-calibration-dd24.ipynb``: the notebook fits
``H = estimate_homography(corners, board, camera)`` (``ransac.py``: ``cv2.findHomography`` from
``camera.pixel2vector(corner)`` = ``K^-1 [u, v, 1]`` of the rectified image to the board's ground points), prints
``H.flatten()`` (the file's nine numbers, equal to 1e-6) and saves it with ``HomographyToolkit.save_to_disk``
unconverted. So the file holds normalized image vectors -> ground in metres, not the resolution-independent
matrix its header announces; Duckietown's current ``load_from_disk`` would refuse it (no ``format`` key), and
reading it through ``camera_specific`` (``Hv2i @ F``) gives no rigid ground at all (checked below).

Its ground frame is the board's own (origin at a corner of the inner-corner grid, axes along the grid, 17 mm
squares: the recovered camera is 5.55 cm above it and 47.5 degrees down, the issue's "about 5.6 cm and 47 degrees"),
z pointing down. No real DD24 photograph is stored here, so the frame is constructed FROM the reference: the
camera placed where the file says, the board (7x5 inner corners, 17 mm) drawn with numpy through the reference
intrinsics at the photographs' 480x640 (``scenario1/calibration-intrinsic-dd24.yaml`` is the same camera with K
doubled), distortion included. The kit calibrates it as a DD24 (exit 0) and its homography, taken to the
board's frame by the placement of ``boards.py`` (``CalibrationBoardDD24``: near row of inner corners at
0.25 + 0.017 m, right column at -0.080 + 0.017 m), agrees with the reference file within 1.5 mm over the board.
"""

from __future__ import annotations

import json
import subprocess
import sys
import warnings

import cv2
import numpy as np
import pytest
from drawn_ground import DD24_COLS as COLS
from drawn_ground import DD24_ROWS as ROWS
from drawn_ground import DD24_SQUARE as SQUARE
from drawn_ground import HOMOGRAPHY, INTRINSICS, REF, board_to_camera, reference, reference_frame
import yaml

NEAR_ROW_X, RIGHT_COL_Y = 0.25 + SQUARE, -0.080 + SQUARE  # boards.py x_offset, y_offset + one square
BOUND_MM = 1.5  # issue 21: "the kit's own homography for it matches Duckietown's reference within 0.15 cm"


def pose(M):
    """(height m, pitch below the ground plane deg, |r2| / |r1|, cos(r1, r2)) of ``[r1 r2 t]``."""
    r1, r2, t = M[:, 0], M[:, 1] / np.linalg.norm(M[:, 1]), M[:, 2]
    R = np.column_stack([r1, r2, np.cross(r1, r2)])
    centre, axis = -R.T @ t, R.T @ [0.0, 0.0, 1.0]
    return (abs(centre[2]), np.degrees(np.arcsin(abs(axis[2]))), np.linalg.norm(M[:, 1]) / np.linalg.norm(M[:, 0]),
            abs(M[:, 0] @ M[:, 1]) / np.linalg.norm(M[:, 0]) / np.linalg.norm(M[:, 1]))


def board_frame_to_robot(b):
    """The reference's board frame -> the robot's (x ahead, y left). The camera sits at +y of the board's frame
    looking towards -y, with the frame's z down, so ahead is -y and left is -x; the near row of inner corners
    (y = 4 squares) is at ``NEAR_ROW_X``, the right-most column (x = 6 squares) at ``RIGHT_COL_Y``."""
    b = np.asarray(b, float)
    return np.column_stack([NEAR_ROW_X + ((ROWS - 1) * SQUARE - b[:, 1]),
                            RIGHT_COL_Y + ((COLS - 1) * SQUARE - b[:, 0])])


def test_the_reference_is_a_rigid_view_of_the_board_from_5_6_cm_and_47_degrees():
    F, K, _, (w, h) = reference()
    height, pitch, ratio, cosine = pose(board_to_camera(F))
    assert abs(height - 0.056) < 0.003 and abs(pitch - 47.0) < 1.0, (height, pitch)
    assert abs(ratio - 1) < 0.02 and cosine < 0.03, (ratio, cosine)  # a plane seen by a calibrated camera
    # the same nine numbers read as Duckietown's current format (camera_specific: Hv2i @ F) are no rigid view
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    tl, br = np.array([-cx / fx, -cy / fy]), np.array([(w - 1 - cx) / fx, (h - 1 - cy) / fy])
    s = 1 / (br - tl)
    Hv2i = np.array([[s[0], 0, -tl[0] * s[0]], [0, s[1], -tl[1] * s[1]], [0, 0, 1]])
    _, _, ratio_i, cosine_i = pose(board_to_camera(Hv2i @ F))
    assert abs(ratio_i - 1) > 0.3 or cosine_i > 0.3, (ratio_i, cosine_i)


def test_the_kit_reads_the_reference_as_duckietown_wrote_it(tmp_path):
    from dtscal_lib import calib_files

    F, K, _, _ = reference()
    calib = calib_files.load_intrinsics(INTRINSICS)
    H, fmt, date = calib_files.read_extrinsic_file(HOMOGRAPHY, calib)
    assert fmt == "2" and date == "2024-08-18T18:29:27.204792"
    rng = np.random.default_rng(21)
    pix = rng.uniform([0, 0], [239, 319], (20, 2))
    vec = (pix - K[:2, 2]) / [K[0, 0], K[1, 1]]  # lib-dt-computer-vision's pixel2vector
    want = np.column_stack([vec, np.ones(len(vec))]) @ F.T
    got = np.column_stack([pix, np.ones(len(pix))]) @ H.T
    np.testing.assert_allclose(got[:, :2] / got[:, 2:], want[:, :2] / want[:, 2:], atol=1e-9)
    # a file the kit writes says its format, as Duckietown's writer does and its reader requires; it reads back
    path = calib_files.save_extrinsics_as(H, tmp_path, "dronebot", fmt="2", intrinsics=calib)
    assert yaml.safe_load(path.read_text())["format"] == "resolution-independent"
    np.testing.assert_allclose(calib_files.read_extrinsic_file(path, calib)[0], H, rtol=1e-9, atol=1e-12)
    # the kit's files from before it wrote the key (its header names it) still read the same way
    older = tmp_path / "older.yaml"
    older.write_text(path.read_text().replace("format: resolution-independent\n", ""))
    assert "format" not in yaml.safe_load(older.read_text())
    np.testing.assert_allclose(calib_files.read_extrinsic_file(older, calib)[0], H, rtol=1e-9, atol=1e-12)
    path.write_text(path.read_text().replace("resolution-independent", "resolution-dependent"))
    with pytest.raises(calib_files.CalibrationFileError, match="format"):
        calib_files.read_extrinsic_file(path, calib)


def test_a_frame_at_the_reference_pose_calibrates_and_agrees_with_the_reference(tmp_path):
    from dtscal_lib import calib_files

    src = tmp_path / "frames"
    src.mkdir()
    frame = reference_frame()
    assert frame.shape == (640, 480)
    cv2.imwrite(str(src / "dd24.png"), frame)
    out = tmp_path / "out"
    p = subprocess.run([sys.executable, "-m", "dtscal_lib.cli", "calibrate-extrinsics", "--source", str(src),
                        "--intrinsics", str(INTRINSICS), "--square", str(SQUARE), "--robot", "dronebot",
                        "--out", str(out), "-q", "--json"], capture_output=True, text=True, timeout=600, check=False)
    assert p.returncode == 0, p.stderr
    cam = json.loads(p.stdout)["camera_pose"]
    F, K, _, _ = reference()
    height, pitch, _, _ = pose(board_to_camera(F))
    assert abs(cam["height_m"] - height) < 0.002 and abs(cam["pitch_down_deg"] - pitch) < 1.0, (cam, height, pitch)
    H_kit = np.array(yaml.safe_load((out / "camera_extrinsic" / "dronebot.yaml").read_text())["homography"],
                     float).reshape(3, 3)
    H_ref, _, _ = calib_files.read_extrinsic_file(HOMOGRAPHY, calib_files.load_intrinsics(INTRINSICS))
    # over the board: its inner corners and a grid across the area they span (the outer squares, extrapolated,
    # reach 1.42 mm), as the rectified 240x320 camera (P = K in the file) sees them, taken to the ground by the
    # kit and by Duckietown's reference (measured: 1.09 mm at most)
    j, i = np.mgrid[0:COLS, 0:ROWS]
    gx, gy = np.meshgrid(np.linspace(0, (COLS - 1) * SQUARE, 25), np.linspace(0, (ROWS - 1) * SQUARE, 17))
    board = np.vstack([np.column_stack([j.ravel(), i.ravel()]) * SQUARE, np.column_stack([gx.ravel(), gy.ravel()])])
    q = np.column_stack([board, np.ones(len(board))]) @ (K @ board_to_camera(F)).T
    pix = np.column_stack([q[:, :2] / q[:, 2:], np.ones(len(q))])
    kit, ref = pix @ H_kit.T, pix @ H_ref.T
    err_mm = 1000 * np.linalg.norm(kit[:, :2] / kit[:, 2:] - board_frame_to_robot(ref[:, :2] / ref[:, 2:]), axis=1)
    print(f"kit vs reference: corners {err_mm[:COLS * ROWS].max():.2f} mm, board {err_mm.max():.2f} mm")
    assert err_mm.max() < BOUND_MM, (err_mm[:COLS * ROWS].max(), err_mm.max())


def test_duckietowns_other_dd24_file_holds_the_same_kind_of_matrix_though_it_says_otherwise():
    """``scenario1/homography.yaml`` carries ``format: resolution-independent`` (and the placeholder date of
    ``save_to_http``'s docstring), yet it too is a rigid view only when read as normalized vectors -> ground:
    its camera (``scenario1/calibration-intrinsic-dd24.yaml``, 480x640, the 240x320 file's K doubled) 6.2 cm above
    the board, 49 degrees down. The kit cannot tell from the file; ``reading="vector"`` says it."""
    from dtscal_lib import calib_files

    _, K, D, (w, h) = reference()
    K2 = K * 2
    K2[2, 2] = 1.0
    calib = calib_files.IntrinsicCalibration("dd24_480_640", 2 * w, 2 * h, K2, "plumb_bob", D, np.eye(3),
                                             np.column_stack([K2, np.zeros(3)]))
    path = REF / "scenario1-homography.yaml"
    rigid = {}
    for reading in (None, "vector"):
        with warnings.catch_warnings():  # H[1][2] > 0: the Duckiebot's sign rule; this ground is the board's frame
            warnings.simplefilter("ignore", calib_files.CalibrationFileWarning)
            H, fmt, _ = calib_files.read_extrinsic_file(path, calib, reading=reading)
        rigid[reading] = pose(board_to_camera(H @ K2))  # back to normalized vectors -> ground
    height, pitch, ratio, cosine = rigid["vector"]
    assert abs(ratio - 1) < 0.05 and cosine < 0.03 and 0.05 < height < 0.07 and 45 < pitch < 52, rigid["vector"]
    assert abs(rigid[None][2] - 1) > 0.3, rigid[None]  # the file's own word: no rigid view
