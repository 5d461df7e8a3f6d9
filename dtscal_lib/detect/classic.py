"""The public detectors: the saddle lattice where it holds, OpenCV's classic detector on the candidate regions
otherwise (live and thorough orders), and ROS's full-frame baseline; each raw detection ordered, refined and checked."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from ..boards import DUCKIETOWN_BOARD, Board, CharucoBoard
from ..duckietown import BORDER_MARGIN_PX
from ..errors import DtscalError
from ..limits import SMOOTH_GRID_TOLERANCE
from .charuco import detect_charuco
from .frame import REASON_AT_BORDER, REASON_INCONSISTENT, REASON_NO_BOARD, Detection, to_gray
from .grid import _local_square, grid_jump, grid_rejection, grid_residuals, grid_tolerance
from .lattice import _saddle_lattice
from .order import order_corners
from .refine import refine_corners, refine_corners_checked
from .saddles import _candidates

#: OpenCV flags of ROS's calibrator (``FAST_CHECK`` is what the live calibrator adds)
ROS_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
#: flags inside a candidate region: no FAST_CHECK (the saddle clusters already did that job,
#: and OpenCV's quick check rejects many tightly cropped boards)
REGION_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
#: a region whose longer side is at most this is tried again at twice the size if the
#: classic detector fails on it (small, far boards: its quads are too small at 1x)
UPSCALE_REGION_SIDE = 240

#: in the live detector, a candidate whose saddles are at least this far apart (pixels) is
#: searched on its region downsampled by 2 (squares of 10 px or more are found there)
HALF_SIZE_SPACING = 20.0


def _near_border(corners: np.ndarray, size: tuple[int, int], margin: float) -> bool:
    w, h = size
    x, y = corners[:, 0], corners[:, 1]
    inside = (x > margin) & (x < w - margin) & (y > margin) & (y < h - margin)
    return not bool(np.all(inside))


def _finish(gray: np.ndarray, raw: np.ndarray, board: Board, border_margin: float,
            ros: bool = False) -> Detection:
    """Order, refine and check a raw detection. ``ros=True`` refines as ROS does (one window,
    :func:`subpix_radius`, no checks): the baseline."""
    h, w = gray.shape
    raw = order_corners(raw, board)
    if ros:
        corners = refine_corners(gray, raw, board)
    else:
        corners, ok = refine_corners_checked(gray, raw, board)
        if not ok:
            # a board running off the image is reported as such (ROS's rule), not as inconsistent
            # ... and so is a board whose corners off the grid have squares the image edge cuts (within a
            # square of it): the edge pulled their refinement, the grid check is its echo
            reach = (border_margin + _local_square(raw, board))[:, None]
            cut = np.any((raw < reach) | (raw > np.array([w - 1.0, h - 1.0]) - reach), axis=1)
            off = ((grid_jump(corners, board) > grid_tolerance(raw, board))
                   | (grid_residuals(corners, board, SMOOTH_GRID_TOLERANCE) > SMOOTH_GRID_TOLERANCE))
            if (_near_border(raw, (w, h), border_margin) or _near_border(corners, (w, h), border_margin)
                    or np.any(cut & off)):
                return Detection(False, raw, REASON_AT_BORDER, board, (w, h))
            return Detection(False, corners, REASON_INCONSISTENT, board, (w, h), grid_rejection(corners, board))
    if _near_border(corners, (w, h), border_margin):
        return Detection(False, corners, REASON_AT_BORDER, board, (w, h))
    return Detection(True, corners, None, board, (w, h))


def _check_inputs(board: Board, border_margin: float) -> None:
    if not isinstance(board, Board):
        raise DtscalError(f"board must be a dtscal_lib.boards.Board, got {type(board).__name__}; "
                          "e.g. parse_board('7x5', 0.031)")
    if not (np.isfinite(border_margin) and border_margin >= 0):
        raise DtscalError(f"border_margin must be a non-negative number of pixels, got {border_margin!r}")


# --------------------------------------------------------------------------- public detectors
def detect_board(image, board: Board = DUCKIETOWN_BOARD, *,
                 border_margin: float = BORDER_MARGIN_PX) -> Detection:
    """Find the board's inner corners, quickly even when there is no board.

    Saddle-point clusters (:func:`board_regions`) select at most two candidate regions;
    OpenCV's classic detector with ROS's flags runs only there; corners are ordered
    (:func:`order_corners`) and refined (:func:`refine_corners_checked`) on the full image.

    Parameters
    ----------
    image : gray, BGR or BGRA frame (see :func:`to_gray`)
    board : the board to look for (inner corners)
    border_margin : reject detections with a corner within this many pixels of the edge

    Returns
    -------
    Detection

    Examples
    --------
    >>> import numpy as np
    >>> detect_board(np.zeros((480, 640), np.uint8)).reason
    'no_board'
    """
    if isinstance(board, CharucoBoard):  # OpenCV's ChArUco detector: partial views, no border rule (ROS's)
        return detect_charuco(image, board)
    _check_inputs(board, border_margin)
    gray = to_gray(image)
    return _detect_in_regions(gray, board, border_margin, live=True)


def _classic(roi: np.ndarray, board: Board, scale: float):
    """The classic detector on ``roi`` resized by ``scale``; corners in ``roi``'s pixels or None."""
    img = roi if scale == 1 else cv2.resize(
        roi, None, fx=scale, fy=scale, interpolation=cv2.INTER_LINEAR if scale > 1 else cv2.INTER_AREA)
    ok, raw = cv2.findChessboardCorners(img, board.pattern_size, flags=REGION_FLAGS)
    if not ok:
        return None
    # pixel centres: resized pixel k sits at (k + 0.5) / scale - 0.5 in the region
    return (raw.reshape(-1, 2).astype(np.float64) + 0.5) / scale - 0.5


def _noted(det: Detection, bigger: tuple[int, int] | None) -> Detection:
    """The detection, with the bigger pattern the saddles showed around it (:attr:`Detection.pattern_seen`)."""
    return det if bigger is None else dataclasses.replace(det, pattern_seen=bigger)


def _same_box(a, b, tol: float) -> bool:
    return all(abs(p - q) <= tol for p, q in zip(a, b))


def _detect_in_regions(gray: np.ndarray, board: Board, border_margin: float, live: bool) -> Detection:
    """Classic detection in the saddle clusters' regions (see :func:`detect_board`).

    ``live=False`` is the original, thorough order: every region at full size, small ones again
    at twice the size. ``live=True`` bounds the work per frame (the classic detector answers
    in 1-5 ms where it finds a board but spends 10-35 ms per region where it does not, mostly
    on boards cut by the image edge, which the border rule would reject anyway):

    - a region whose box differs from an already tried one by at most a square on each side
      is skipped (a split board's merged box and the seed's own box are often nearly the same);
    - a cluster of large squares (saddle spacing at least :data:`HALF_SIZE_SPACING`) is first
      searched on the region downsampled by 2 (squares of 10 px or more are still found there, at
      a quarter of the cost); only if the board is found there is the full-size search made, whose
      corners are used (so they are those of the thorough order);
    - the 2x retry of small regions is not made for a region that touches the image edge (a
      small board there is nearly always cut by the edge).
    """
    h, w = gray.shape
    tried: list[tuple[int, int, int, int]] = []
    for cand in _candidates(gray, board):
        x0, y0, x1, y1 = cand.box
        roi = gray[y0:y1, x0:x1]
        if min(roi.shape) < 16:  # OpenCV's adaptive threshold needs a few pixels
            continue
        if live and any(_same_box(cand.box, t, cand.spacing) for t in tried):
            continue
        tried.append(cand.box)
        seen: dict = {}
        if live:
            # the board straight from the saddles where they form exactly its grid; the classic
            # detector only where they do not, or where the refinement's checks reject the result
            lattice = _saddle_lattice(cand, board, seen)
            if lattice is not None:
                det = _finish(gray, lattice, board, border_margin)
                if det.found or det.reason == REASON_AT_BORDER:
                    return det
        bigger = seen.get("pattern")
        if live and cand.spacing >= HALF_SIZE_SPACING:
            # a quick test at half size; the corners then come from the full-size search as in
            # the thorough order (the same start, so the same refined corners), or from the
            # half-size one if the full-size search fails
            half = _classic(roi, board, 0.5)
            if half is None:
                continue
            raw = _classic(roi, board, 1.0)
            raw = half if raw is None else raw
            return _noted(_finish(gray, raw + (x0, y0), board, border_margin), bigger)
        else:
            scales = [1.0]
            at_edge = x0 == 0 or y0 == 0 or x1 == w or y1 == h
            if max(roi.shape) <= UPSCALE_REGION_SIDE and not (live and at_edge):
                scales.append(2.0)
        for scale in scales:
            raw = _classic(roi, board, scale)
            if raw is not None:
                return _noted(_finish(gray, raw + (x0, y0), board, border_margin), bigger)
    return Detection(False, None, REASON_NO_BOARD, board, (w, h))


def detect_board_ros(image, board: Board = DUCKIETOWN_BOARD, *,
                     border_margin: float = BORDER_MARGIN_PX) -> Detection:
    """The ROS ``camera_calibration`` baseline: the classic detector on the full frame.

    ``findChessboardCorners(ADAPTIVE_THRESH | NORMALIZE_IMAGE | FAST_CHECK)`` on the whole
    image, then the same ordering and border rule as :func:`detect_board` and ROS's refinement
    (one ``cornerSubPix`` window of :func:`subpix_radius` for all corners, no checks).
    Kept as the reference for benchmarks and tests; can take hundreds of milliseconds on a
    cluttered frame without a board.
    """
    _check_inputs(board, border_margin)
    gray = to_gray(image)
    h, w = gray.shape
    ok, raw = cv2.findChessboardCorners(gray, board.pattern_size, flags=ROS_FLAGS)
    if not ok:
        return Detection(False, None, REASON_NO_BOARD, board, (w, h))
    return _finish(gray, raw.reshape(-1, 2).astype(np.float64), board, border_margin, ros=True)


def detect_board_still(image, board: Board = DUCKIETOWN_BOARD, *,
                       border_margin: float = BORDER_MARGIN_PX) -> Detection:
    """Thorough detection for a single still frame, where time does not matter.

    :func:`detect_board` first (so both refine identically where it finds the board); when it
    finds nothing, the candidate regions again with every attempt the live path skips to bound
    its time (full size, 2x retries), then OpenCV's classic detector on the
    whole frame with ``ADAPTIVE_THRESH | NORMALIZE_IMAGE`` and no ``FAST_CHECK``, as
    Duckietown's extrinsic calibration runs it. On a rectified floor view the far squares
    are only about 12 px tall; ``FAST_CHECK`` and the region search can miss such a board
    that the full search finds. Too slow for a live stream on a board-free frame (up to a
    few hundred ms); meant for the extrinsic capture and for notebooks.
    """
    det = detect_board(image, board, border_margin=border_margin)
    if det.found or det.reason == REASON_AT_BORDER or isinstance(board, CharucoBoard):
        return det
    gray = to_gray(image)
    thorough = _detect_in_regions(gray, board, border_margin, live=False)
    if thorough.found or thorough.reason == REASON_AT_BORDER:
        return thorough
    ok, raw = cv2.findChessboardCorners(gray, board.pattern_size, flags=REGION_FLAGS)
    if not ok:
        return det
    return _finish(gray, raw.reshape(-1, 2).astype(np.float64), board, border_margin)
