"""The saddle lattice: the board's corners straight from the saddle clusters, without the classic detector.

``detect.lattice._saddle_lattice`` walks the saddles of a candidate cluster as a grid; where they form exactly the
board's ``rows x cols`` window with a weaker ring around it, the classic detector is not run. These tests pin
what makes that safe, on OpenCV's real sample photographs (data/real, 9x6) and on rendered frames:

* the lattice gives the board in (nearly) every real view, and the refined corners are those the classic
  detector's start gives (to a hundredth of a pixel median: the refinement, not the start, sets them);
* a board searched with the wrong size (a 7x5 or 8x6 window of the 9x6 board) is refused by the lattice's
  ring test (the decision is then the classic detector's, as before the lattice: it takes an 8x6 or 7x6
  window of these photographs in 23 and 20 of 26 views, a 7x5, 9x5 or 8x5 one in at most 1);
* the corners are in a row-major order of the board, whichever axis the walk started on.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from dtscal_lib import detect as D
from dtscal_lib.detect.classic import _finish
from dtscal_lib.detect.lattice import _saddle_lattice
from dtscal_lib.detect.saddles import _Candidate, _candidates
from dtscal_lib.boards import DUCKIETOWN_BOARD, Board, parse_board

REAL = Path(__file__).resolve().parents[1] / "data" / "real" / "opencv-samples"
BOARD = Board(cols=9, rows=6, square=0.03)


@pytest.fixture(scope="module")
def photos() -> list[np.ndarray]:
    files = sorted(REAL.glob("*/*.jpg"))
    assert len(files) == 26, f"expected the 26 OpenCV sample photographs in {REAL}"
    return [cv2.imread(str(f), cv2.IMREAD_GRAYSCALE) for f in files]


def _lattice(gray, board):
    for cand in _candidates(gray, board):
        grid = _saddle_lattice(cand, board)
        if grid is not None:
            return grid
    return None


def test_lattice_finds_the_real_boards(photos):
    # measured: 24 of 26 (the two others have a ring saddle as strong as the board's weakest corner and go
    # to the classic detector); 20 leaves room for other OpenCV builds' resizing, not for a broken walk
    grids = [_lattice(g, BOARD) for g in photos]
    assert sum(g is not None for g in grids) >= 20
    for g, grid in zip(photos, grids):
        if grid is None:
            continue
        assert grid.shape == (BOARD.n_corners, 2)
        # a row-major order of the board: once ordered, each corner is the classic detector's same corner
        ok, classic = cv2.findChessboardCorners(g, BOARD.pattern_size, flags=D.REGION_FLAGS)
        assert ok
        a = D.order_corners(grid, BOARD)
        b = D.order_corners(classic.reshape(-1, 2).astype(np.float64), BOARD)
        assert np.linalg.norm(a - b, axis=1).max() < 6.0  # the saddles are found at half size: a few pixels


def test_lattice_start_refines_to_the_classic_start_corners(photos):
    """The start changes the refined corners only where the polish step's 0.1 px rule flips (measured: median
    0.0001 px, worst 0.14 px over the 26 views); a start a pixel off that the refinement did not pull in would
    show as a median of tenths of a pixel."""
    diffs = []
    for g in photos:
        grid = _lattice(g, BOARD)
        ok, classic = cv2.findChessboardCorners(g, BOARD.pattern_size, flags=D.REGION_FLAGS)
        if grid is None or not ok:
            continue
        a = _finish(g, grid, BOARD, 8.0)
        b = _finish(g, classic.reshape(-1, 2).astype(np.float64), BOARD, 8.0)
        assert a.found and b.found
        diffs.append(np.linalg.norm(a.corners - b.corners, axis=1))
    d = np.concatenate(diffs)
    assert len(diffs) >= 20
    assert np.median(d) < 0.01
    assert d.max() < 0.3


@pytest.mark.parametrize("size", ["7x5", "8x6", "9x5", "8x5", "7x6"])
def test_a_window_of_a_bigger_board_is_refused(photos, size):
    """Measured on every candidate window: none passes both ring rules (see detect.LATTICE_RING_RATIO)."""
    board = parse_board(size)
    for g in photos:
        assert _lattice(g, board) is None


def test_lattice_gives_up_on_scattered_saddles():
    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 400, size=(80, 2))
    cand = _Candidate((0, 0, 400, 400), pts, 30.0, rng.uniform(1, 2, size=80))
    assert _saddle_lattice(cand, BOARD) is None


def test_lattice_reads_a_perfect_grid_in_either_axis_order():
    j, i = np.mgrid[0:BOARD.rows, 0:BOARD.cols]
    grid = np.column_stack([100 + 30.0 * i.ravel(), 80 + 30.0 * j.ravel()])
    for pts in (grid, grid[:, ::-1].copy()):  # the transposed image: rows become columns
        cand = _Candidate((0, 0, 600, 600), pts, 30.0, np.ones(len(pts)))
        out = _saddle_lattice(cand, BOARD if pts is grid else Board(cols=6, rows=9, square=0.03))
        assert out is not None
        assert sorted(map(tuple, out)) == sorted(map(tuple, pts))


def test_recording_windows_of_the_wrong_size_are_refused():
    """The recorded session's 7x5 board searched as smaller boards (every 20th frame): no window accepted."""
    from dtscal_lib.sources import open_source

    session = Path(__file__).resolve().parents[1] / "data" / "session" / "intrinsics.bag"
    frames = [D.to_gray(f.image) for k, f in enumerate(open_source(str(session))) if k % 20 == 0]
    assert len(frames) >= 20
    right = 0
    for gray in frames:
        right += _lattice(gray, DUCKIETOWN_BOARD) is not None
        for size in ("6x4", "5x5", "6x5", "7x4", "5x4"):
            assert _lattice(gray, parse_board(size)) is None, size
    assert right >= 0.8 * sum(D.detect_board(g).found for g in frames)
