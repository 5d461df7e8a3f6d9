"""Curled and wavy prints: real photographs bent smoothly are found; one displaced corner is not.

A printed board is rarely flat: the paper curls, so the grid of corners bends smoothly by a few
pixels over the board, while a corner the detector put in the wrong place jumps away from its
neighbours. The images here are OpenCV's real sample photographs (``data/real/``) warped with
``cv2.remap`` by a smooth displacement field (a print curling up at both sides, 12 px at the
board's edges, on copies scaled to Duckietown's square size in the image), so their corner truth is
the unwarped detection carried through the field; wavy prints likewise (full size, waves of 5 px
amplitude and 300 px wavelength). The kit's grid check (``detect.grid_jump``, the quadratic
through each corner's 8 neighbours) must let these through with their corners accurate, where a
homography through the neighbours (the check before, ``detect.grid_disagreement``) is off by more
than its tolerance; and a corner moved alone by a local bump must still reject the board,
found-and-rejected, naming that corner.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from dtscal_lib.boards import parse_board
from dtscal_lib.detect import (GRID_TOLERANCE_FRACTION, GRID_TOLERANCE_PX, detect_board_still, grid_disagreement,
                               grid_jump, grid_tolerance)

REAL = Path(__file__).resolve().parents[1] / "data" / "real" / "opencv-samples"
BOARD = parse_board("9x6", 0.03)
#: photographs whose 0.6x copy curled by 12 px the former check (a homography through the 8 neighbours)
#: refused; benchmarks/grid_tolerance.py runs all 26
PHOTOS = ("left/left02.jpg", "left/left12.jpg", "right/right05.jpg", "right/right12.jpg")
SCALE = 0.6  # squares of 13-18 px, as Duckietown's 17 mm squares on the floor
CURL_PX = 12.0


def _curl(c: np.ndarray, amp: float):
    """A print curling up at both sides: ``(0.15 A u^3, A u^2)``, ``u`` in half board widths from the centre."""
    cx, half = c[:, 0].mean(), np.ptp(c[:, 0]) / 2

    def d(x, y):
        u = (x - cx) / half
        return 0.15 * amp * u ** 3, amp * u ** 2
    return d


def _warp(img: np.ndarray, d) -> np.ndarray:
    """The image seen through the field: pixel p shows what the flat print had at p + d(p)."""
    h, w = img.shape
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    dx, dy = d(x, y)
    return cv2.remap(img, (x + dx).astype(np.float32), (y + dy).astype(np.float32), cv2.INTER_CUBIC,
                     borderMode=cv2.BORDER_REPLICATE)


def _carried(d, p: np.ndarray) -> np.ndarray:
    """Where the flat print's points ``p`` appear in the warped image: q with q + d(q) = p."""
    q = p.copy()
    for _ in range(60):
        dx, dy = d(q[:, 0], q[:, 1])
        q = p - np.column_stack([dx, dy])
    return q


@pytest.fixture(scope="module")
def flat():
    out = {}
    for name in PHOTOS:
        img = cv2.imread(str(REAL / name), cv2.IMREAD_GRAYSCALE)
        assert img is not None, f"missing {REAL / name}"
        img = cv2.resize(img, None, fx=SCALE, fy=SCALE, interpolation=cv2.INTER_AREA)
        det = detect_board_still(img, BOARD)
        assert det.found, f"{name}: the unwarped photograph must be found"
        out[name] = (img, det.corners)
    return out


def test_smoothly_curled_real_boards_are_found_with_accurate_corners(flat):
    homography_would_refuse = 0
    for name, (img, corners) in flat.items():
        d = _curl(corners, CURL_PX)
        truth = _carried(d, corners)
        bend = np.linalg.norm(truth - corners, axis=1)
        assert bend.max() > 3.0, f"{name}: the warp must bend the grid by several px"
        det = detect_board_still(_warp(img, d), BOARD)
        assert det.found, f"{name}: curled board refused: {det.reason}: {det.detail}"
        err = np.linalg.norm(det.corners - truth, axis=1)
        assert err.max() < 0.3, f"{name}: worst corner {err.max():.2f} px from the warped truth"
        assert np.all(grid_jump(det.corners, BOARD) <= grid_tolerance(det.corners, BOARD))
        # the homography through the 8 neighbours, with the former tolerance, cannot follow the bend
        old_tol = np.maximum(0.75, 0.1 * np.min(np.linalg.norm(np.diff(
            truth.reshape(BOARD.rows, BOARD.cols, 2), axis=1), axis=2)))
        inner = np.zeros((BOARD.rows, BOARD.cols), bool)
        inner[1:-1, 1:-1] = True
        homography_would_refuse += bool(np.nanmax(grid_disagreement(truth, BOARD)[inner.ravel()]) > old_tol)
    assert homography_would_refuse == len(PHOTOS), "the test set must hold bends the former check refused"


def test_one_displaced_corner_is_found_and_rejected_by_name(flat):
    img = cv2.imread(str(REAL / "left/left01.jpg"), cv2.IMREAD_GRAYSCALE)
    corners = detect_board_still(img, BOARD).corners
    k = 3 * BOARD.cols + 4  # row 4, column 5 (from 1): an inner corner
    c = corners[k]
    g = corners.reshape(BOARD.rows, BOARD.cols, 2)
    square = float(np.linalg.norm(g[3, 5] - g[3, 4]))
    shift = 0.25 * square  # a quarter of a square, beyond the tolerance of a tenth
    assert shift > max(GRID_TOLERANCE_PX, GRID_TOLERANCE_FRACTION * square) * 1.5
    sigma = 0.35 * square  # a bump local to the corner: its neighbours stay (almost) where they are

    def d(x, y):
        w = np.exp(-((x - c[0]) ** 2 + (y - c[1]) ** 2) / (2 * sigma ** 2))
        return -shift * w, 0.0 * w
    det = detect_board_still(_warp(img, d), BOARD)
    assert not det.found and det.reason == "inconsistent_grid"
    assert det.corners is not None and det.corners.shape == (BOARD.n_corners, 2)  # found, then rejected
    assert det.detail.startswith("corner at row 4, column 5 "), det.detail
    dist = float(det.detail.split(" is ")[1].split(" px")[0])
    assert dist > GRID_TOLERANCE_PX


@pytest.mark.parametrize("phase", [0.0, 2.0])
def test_wavy_real_boards_are_found_with_accurate_corners(phase):
    k = 2 * np.pi / 300.0  # waves of 300 px, 5 px amplitude

    def d(x, y):
        return (5.0 * np.sin(k * x + phase) * np.cos(0.7 * k * y),
                5.0 * np.sin(k * y + 1.3 * phase) * np.cos(0.6 * k * x))
    for name in ("left/left04.jpg", "left/left09.jpg", "right/right06.jpg", "right/right11.jpg"):
        img = cv2.imread(str(REAL / name), cv2.IMREAD_GRAYSCALE)
        truth = _carried(d, detect_board_still(img, BOARD).corners)
        det = detect_board_still(_warp(img, d), BOARD)
        assert det.found, f"{name}: wavy board refused: {det.reason}: {det.detail}"
        assert np.linalg.norm(det.corners - truth, axis=1).max() < 0.3


def test_extrinsics_say_found_and_rejected_naming_the_corner(monkeypatch):
    """The extrinsic procedure reports a board the grid check rejected as found-and-rejected, never 'not found'."""
    from dtscal_lib import duckietown as dt
    from dtscal_lib import ground
    from dtscal_lib.boards import DUCKIETOWN_BOARD
    from dtscal_lib.camera import CameraModel
    from dtscal_lib.detect import Detection
    from dtscal_lib.errors import CalibrationError

    detail = "corner at row 3, column 4 (pixel 320.0, 300.0) is 2.40 px from where its 8 neighbours put it " \
             "(tolerance 1.60 px)"
    rejected = Detection(False, np.zeros((DUCKIETOWN_BOARD.n_corners, 2)), "inconsistent_grid", DUCKIETOWN_BOARD,
                         (640, 480), detail)
    monkeypatch.setattr(ground, "detect_board_still", lambda *a, **k: rejected)
    camera = CameraModel(dt.default_K(), dt.default_dist(), dt.IMAGE_SIZE)
    with pytest.raises(CalibrationError) as e:
        ground.extrinsics_from_image(np.zeros((480, 640, 3), np.uint8), camera)
    assert e.value.reason == "inconsistent_grid"
    msg = str(e.value)
    assert "was found in the rectified image but rejected: corner at row 3, column 4" in msg and "2.40 px" in msg
    assert "not found" not in msg


@pytest.mark.parametrize("name", ["left/left01.jpg", "right/right03.jpg"])
def test_one_displaced_corner_on_the_outer_ring_is_rejected_by_name(name):
    """The outer ring is checked too (from the 3x3 block reaching inward): 0.12 of a square is caught.

    (A bump much larger than that, a third of its own width, folds the image so that the detector finds
    the corner back on its neighbours' grid, within 0.3 px of where the flat print had it.)"""
    img = cv2.imread(str(REAL / name), cv2.IMREAD_GRAYSCALE)
    corners = detect_board_still(img, BOARD).corners
    k = 4  # row 1, column 5: the middle of the first row
    c = corners[k]
    square = float(np.linalg.norm(corners[5] - corners[4]))
    shift, sigma = 0.12 * square, 0.35 * square

    def d(x, y):
        w = np.exp(-((x - c[0]) ** 2 + (y - c[1]) ** 2) / (2 * sigma ** 2))
        return -shift * w, 0.0 * w
    det = detect_board_still(_warp(img, d), BOARD)
    assert not det.found and det.reason == "inconsistent_grid"
    assert det.detail.startswith("corner at row 1, column 5 "), det.detail
