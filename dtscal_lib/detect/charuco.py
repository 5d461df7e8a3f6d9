"""ChArUco boards: OpenCV's own ``CharucoDetector`` (objdetect), with ROS's acceptance rule.

A ChArUco view is a *subset* of the board's inner corners, each with its id (:class:`CharucoBoard`'s
numbering), so a wide lens can be calibrated out to its image corners where a whole chessboard never fits.
The markers are found and the chessboard corners between them interpolated and refined to sub-pixel by
OpenCV (``cv2.aruco.CharucoDetector.detectBoard``, the detector OpenCV 4.7+ ships in ``objdetect``).

ROS's rule (image_pipeline, camera_calibration/calibrator.py ``_get_charuco_corners``): a view counts when
more than 5 corners were interpolated. Unlike the chessboard, ROS applies no border margin to ChArUco
corners (each one is interpolated from the markers around it, not walked from the board's outline), and
neither does the kit.

OpenCV's corners are not used as they come. ``detectBoard`` of OpenCV 4.7-4.12 returns every corner
shifted by +0.5 px (it moves the start by -0.5 px before ``cornerSubPix`` and adds 0.5 px after it:
opencv/opencv issue #25539, fixed by pull request #28380 in January 2026), and its refinement windows may
reach the markers' edges, which pull a corner the way a printed outline pulls a chessboard corner. The kit
refines each corner again like a chessboard corner (:func:`charuco_windows`: the window stays inside the
square around the corner that no marker reaches, then the kit's polish on the smoothed image), starting from
OpenCV's corner less OpenCV's offset, measured once on a board OpenCV draws itself (:func:`opencv_offset`:
+0.49 px with the pinned 4.12, 0 once fixed). The refinement alone removes the bias; the measured offset
only gives it a closer start (0.071 against 0.073 px rms on the sweep below).

Measured on the 33 views of the rendered sweep (a 45 mm board, ``benchmarks/bench_charuco.py``), the
corners' error is 0.071 px rms with 27 mm markers (0.6 of the square; p99 0.15 px; the kit's chessboard
corners on the same poses: 0.03-0.05 px) but 0.160 px rms with 34 mm markers (0.76; 17 of 1072 corners off
by more than 0.5 px): the thinner the white margin around the markers, the smaller each corner's window.

A view without four corners spanning a rectangle of the board (two rows and two columns) gives neither a
reliable homography nor ROS's coverage parameters (:func:`~dtscal_lib.coverage.largest_rectangle`): it is
refused here, named, rather than by the calibration later.
"""

from __future__ import annotations

import cv2
import numpy as np

from ..boards import CharucoBoard
from ..coverage import largest_rectangle
from ..errors import DtscalError, Reason
from .frame import Detection, to_gray
from .refine import INNER_REACH, REFINE_SIGMA, WINDOW_MARGIN_PX, _polish_points, _subpix

#: ROS accepts a ChArUco view with more than 5 corners (``len(square_corners) > 5``, calibrator.py)
MIN_CHARUCO_CORNERS = 6

_DETECTORS: dict = {}


def _detector(board: CharucoBoard):
    det = _DETECTORS.get(board)
    if det is None:
        det = cv2.aruco.CharucoDetector(board.opencv_board())
        _DETECTORS[board] = det
    return det


def detect_charuco(image, board: CharucoBoard) -> Detection:
    """The board's visible inner corners and their ids (``Detection.ids``), or why none count.

    Returns
    -------
    Detection
        ``found`` with ``corners`` (N, 2) float64 and ``ids`` (N,) int, sorted by id, when at least
        :data:`MIN_CHARUCO_CORNERS` corners not all on one board line were found; else ``reason`` is
        ``"no_board"`` (``detail`` says how many corners were seen).

    Examples
    --------
    >>> b = CharucoBoard.from_squares(6, 5, 0.04, 0.03, "4x4_50")
    >>> img = b.opencv_board().generateImage((600, 500), marginSize=40)
    >>> d = detect_charuco(img, b)
    >>> d.found, len(d.ids)
    (True, 20)
    """
    if not isinstance(board, CharucoBoard):
        raise DtscalError(f"detect_charuco needs a CharucoBoard, got {type(board).__name__}")
    gray = to_gray(image)
    size = (int(gray.shape[1]), int(gray.shape[0]))
    corners, ids, _, _ = _detector(board).detectBoard(gray)
    n = 0 if ids is None else len(ids)
    if n < MIN_CHARUCO_CORNERS:
        return Detection(False, None, Reason.NO_BOARD, board, size,
                         detail=f"{n} ChArUco corner{'s' if n != 1 else ''} seen; a view needs "
                                f"{MIN_CHARUCO_CORNERS} (ROS's rule)")
    ids = np.asarray(ids, dtype=np.int64).ravel()
    pts = np.asarray(corners, dtype=np.float64).reshape(-1, 2) - opencv_offset()
    order = np.argsort(ids, kind="stable")
    ids, pts = ids[order], pts[order]
    try:
        largest_rectangle(ids, board)
    except DtscalError:
        return Detection(False, None, Reason.NO_BOARD, board, size,
                         detail=f"{n} ChArUco corners seen, but no four of them span a rectangle of the board (two "
                                "rows and two columns): move the board so more of it shows")
    radius = charuco_windows(pts, ids, board)
    pts = _subpix(gray, pts, radius)
    pts = _polish_points(gray, pts, np.maximum(1, radius - int(np.ceil(REFINE_SIGMA))))[0]
    return Detection(True, pts, None, board, size, ids=ids)


def charuco_windows(corners: np.ndarray, ids: np.ndarray, board: CharucoBoard) -> np.ndarray:
    """Per-corner ``cornerSubPix`` half-size that stays inside the marker-free square around each corner.

    Around an inner corner nothing but the corner's own four square edges lies within ``(square - marker) / 2``
    of it on the board (the markers sit centred in the white squares). That square, mapped into the image by
    the view's homography (its local linear part at the corner), bounds the window as
    :func:`~dtscal_lib.detect.corner_windows` bounds a chessboard corner's: ``INNER_REACH`` of the distance to
    each side, less ``WINDOW_MARGIN_PX``; at least 2.
    """
    obj = board.object_points()[ids, :2]
    H, _ = cv2.findHomography(obj, corners, 0)
    if H is None:
        return np.full(len(ids), 2, dtype=int)
    m = (board.square - board.marker) / 2.0
    x = np.column_stack([obj, np.ones(len(obj))]) @ H.T
    w = x[:, 2:3]
    # d pixel / d board of the homography at each corner, (N, 2, 2): columns along board x and y
    J = (H[None, :2, :2] * w[..., None] - x[:, :2, None] * H[None, 2:3, :2]) / (w[..., None] ** 2)
    room = []
    for axis in (0, 1):
        a, o = J[:, :, axis], J[:, :, 1 - axis]
        n = np.stack([-o[:, 1], o[:, 0]], axis=1)
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        dist = np.abs((n * a).sum(axis=1)) * m
        room.append((INNER_REACH * dist - WINDOW_MARGIN_PX) / np.abs(n).sum(axis=1))
    return np.maximum(2, np.floor(np.min(room, axis=0))).astype(int)


_OFFSET: list = []


def opencv_offset() -> np.ndarray:
    """OpenCV's own bias on ChArUco corners (x, y) px, measured once on a board it draws (opencv#25539).

    A 6x5-square board drawn at 60 px per square has its inner corners exactly at ``60 k - 0.5`` px (pixel
    centres at integers); the mean of ``detectBoard``'s corners minus these is the offset, rounded to 0.01 px.
    """
    if not _OFFSET:
        b = CharucoBoard.from_squares(6, 5, 0.06, 0.036, "4x4_50")
        img = b.opencv_board().generateImage((360, 300), marginSize=0)
        img = cv2.copyMakeBorder(img, 40, 40, 40, 40, cv2.BORDER_CONSTANT, value=255)
        corners, ids, _, _ = _detector(b).detectBoard(img)
        if ids is None or len(ids) < MIN_CHARUCO_CORNERS:
            _OFFSET.append(np.zeros(2))
        else:
            truth = b.object_points()[np.asarray(ids).ravel(), :2] / 0.06 * 60.0 + 60.0 + 40.0 - 0.5
            _OFFSET.append(np.round((np.asarray(corners).reshape(-1, 2) - truth).mean(axis=0), 2))
    return _OFFSET[0]
