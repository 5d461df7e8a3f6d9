"""Coverage of a calibration session: ROS ``camera_calibration``'s X / Y / Size / Skew bars.

Each detection is summarised by four numbers computed from the outer four inner corners
(the corners of the corner grid, named as ROS names them: ``up_left = corners[0]``,
``up_right = corners[cols-1]``, ``down_right = corners[-1]``, ``down_left = corners[-cols]``):

* ``area``: area of the quadrilateral of these four corners; ``border = sqrt(area)``;
* ``X = clamp((mean_x - border/2) / (w - border), 0, 1)``: where the board is, left (0) to
  right (1), ``Y`` likewise top (0) to bottom (1);
* ``Size = sqrt(area / (w h))``: how much of the image the board covers;
* ``Skew = min(1, 2 |pi/2 - angle at up_right|)``: how tilted the board is.

A detection becomes a *sample* when its parameters are farther than 0.2 (L1 distance) from
every stored sample; the first one is always taken. The bars show, over all samples, the
range of X and Y (``(max - min) / 0.7``) and the largest Size and Skew (``max / 0.4`` and
``max / 0.5``), capped at 1. CALIBRATE is enabled when every bar is full, or at 40 samples.

Only :class:`CoverageTracker` holds state; :func:`board_params` is a pure function.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .boards import DUCKIETOWN_BOARD, Board
from .camera import as_points, as_size
from .duckietown import IMAGE_SIZE, MAX_SAMPLES_FOR_CALIBRATE, PARAM_RANGES, SAMPLE_MIN_DISTANCE
from .errors import DtscalError

PARAM_NAMES = ("X", "Y", "Size", "Skew")


# --------------------------------------------------------------------------- pure functions
def _as_corners(corners, board: Board) -> np.ndarray:
    c = as_points(corners, 2, "corners")
    if len(c) != board.n_corners:
        raise DtscalError(
            f"expected ({board.n_corners}, 2) corners for a {board.describe()} board, got shape {np.shape(corners)}; "
            "pass the corners of one detection in the board's row-major order"
        )
    return c


def outside_corners(corners: np.ndarray, board: Board = DUCKIETOWN_BOARD) -> np.ndarray:
    """The grid's outer four corners ``[up_left, up_right, down_right, down_left]``, (4, 2).

    ROS's naming: ``corners[0], corners[cols-1], corners[-1], corners[-cols]``.
    """
    c = _as_corners(corners, board)
    return c[list(board.outer_corner_indices())].copy()


def quad_area(quad: np.ndarray) -> float:
    """Area of a quadrilateral ``(4, 2)`` given in order: half the cross product of its diagonals."""
    q = np.asarray(quad, dtype=np.float64).reshape(4, 2)
    p = q[3] - q[1]  # down_left - up_right
    d = q[2] - q[0]  # down_right - up_left
    return float(abs(p[0] * d[1] - p[1] * d[0]) / 2.0)


def skew_angle(quad: np.ndarray) -> float:
    """Angle (radians) at ``up_right`` between the edges to ``up_left`` and ``down_right``."""
    q = np.asarray(quad, dtype=np.float64).reshape(4, 2)
    a, b = q[0] - q[1], q[2] - q[1]
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    if na == 0 or nb == 0:
        raise DtscalError("degenerate detection: two outer corners coincide; drop this detection")
    return float(math.acos(float(np.clip(np.dot(a, b) / (na * nb), -1.0, 1.0))))


def largest_rectangle(ids, board: Board) -> tuple[int, int, int, int]:
    """Ids ``(up_left, up_right, down_right, down_left)`` of the largest grid rectangle whose four corners a
    partial ChArUco view holds: ROS's ``_get_largest_rectangle_corners`` (image_pipeline, calibrator.py), which
    stands in for the outer corners in the X / Y / Size / Skew parameters of a partial view.

    >>> from dtscal_lib.boards import CharucoBoard
    >>> b = CharucoBoard.from_squares(5, 4, 0.04, 0.03, "4x4_50")   # 4x3 inner corners, ids 0..11
    >>> largest_rectangle([0, 1, 2, 4, 5, 6, 9, 10], b)
    (0, 2, 6, 4)
    """
    seen = {int(i) for i in np.asarray(ids).ravel()}
    best, best_area = None, 0
    for x1 in range(board.cols):  # a rectangle spans two columns and two rows (ROS's allows one: a line)
        for x2 in range(x1 + 1, board.cols):
            for y1 in range(board.rows):
                for y2 in range(y1 + 1, board.rows):
                    quad = (y1 * board.cols + x1, y1 * board.cols + x2, y2 * board.cols + x2, y2 * board.cols + x1)
                    area = (x2 - x1 + 1) * (y2 - y1 + 1)
                    if area > best_area and all(q in seen for q in quad):
                        best, best_area = quad, area
    if best is None:
        raise DtscalError("no four corners of a rectangle of the board are among the ChArUco corners seen; "
                          "such a view gives no X / Y / Size / Skew: hold more of the board in view")
    return best


def board_params(corners, board: Board = DUCKIETOWN_BOARD, image_size=IMAGE_SIZE, ids=None) -> np.ndarray:
    """ROS's per-detection parameters ``[X, Y, Size, Skew]``.

    Parameters
    ----------
    corners : (N, 2) float pixels, board row-major order (N = board.n_corners), or the corners of a partial
        ChArUco view with their ``ids``
    board : Board
    image_size : (w, h)
    ids : (N,) ids of a ChArUco view's corners: the quadrilateral is then the largest rectangle of corners
        seen (:func:`largest_rectangle`, ROS's rule for partial views), X and Y the mean of the corners seen

    Returns
    -------
    (4,) float64 ``[X, Y, Size, Skew]``, each in [0, 1] except Size, which can exceed 1
    only for impossible inputs (a quadrilateral bigger than the image).

    Notes
    -----
    When the board's ``border = sqrt(area)`` is at least the image's width (or height) ROS
    would divide by zero or a negative number; here X (or Y) is 0.5 (the board fills that
    axis).

    Examples
    --------
    A fronto-parallel board in the middle of the image has X = Y = 0.5 and Skew = 0:

    >>> from dtscal_lib.boards import Board
    >>> b = Board(3, 2, 1.0)
    >>> c = [[300, 220], [320, 220], [340, 220], [300, 260], [320, 260], [340, 260]]
    >>> board_params(c, b, (640, 480)).round(3).tolist()
    [0.5, 0.5, 0.072, 0.0]
    """
    w, h = as_size(image_size, name="image_size")
    if ids is None:
        c = _as_corners(corners, board)
        quad = c[list(board.outer_corner_indices())]
    else:
        c = as_points(corners, 2, "corners")
        where = {int(k): n for n, k in enumerate(np.asarray(ids).ravel())}
        if len(where) != len(c):
            raise DtscalError(f"got {len(c)} corners but {len(where)} distinct ids; pass one id per corner")
        quad = c[[where[k] for k in largest_rectangle(ids, board)]]
    area = quad_area(quad)
    skew = min(1.0, 2.0 * abs(math.pi / 2.0 - skew_angle(quad)))
    border = math.sqrt(area)

    def position(mean: float, extent: int) -> float:
        if extent - border <= 0:
            return 0.5
        return min(1.0, max(0.0, (mean - border / 2.0) / (extent - border)))

    px = position(float(c[:, 0].mean()), w)
    py = position(float(c[:, 1].mean()), h)
    size = math.sqrt(area / (w * h))
    return np.array([px, py, size, skew], dtype=np.float64)


def param_distance(p1, p2) -> float:
    """L1 distance between two ``[X, Y, Size, Skew]`` vectors."""
    return float(np.sum(np.abs(np.asarray(p1, dtype=np.float64) - np.asarray(p2, dtype=np.float64))))


# --------------------------------------------------------------------------- the tracker
@dataclass(frozen=True)
class Sample:
    """One stored detection: ``corners`` (N, 2) float64 pixels, ``params`` (4,) [X, Y, Size, Skew];
    ``ids`` (N,) for a ChArUco view (its corners' ids), None for a whole chessboard."""

    corners: np.ndarray
    params: np.ndarray
    frame_index: int
    ids: np.ndarray | None = None


@dataclass(frozen=True)
class Bar:
    """One coverage bar: ``progress`` in [0, 1]; ``full`` (green) when progress reaches 1."""

    name: str
    lo: float
    hi: float
    progress: float
    full: bool


class CoverageTracker:
    """Collects calibration samples the way ROS's calibrator does and reports the bars.

    Parameters
    ----------
    board : Board
    image_size : (w, h)
    min_distance : a detection is a new sample if its L1 parameter distance to every
        stored sample exceeds this (ROS: 0.2)
    param_ranges : what a full X, Y, Size, Skew bar needs (ROS: 0.7, 0.7, 0.4, 0.5)
    max_samples : CALIBRATE is enabled at this many samples even with bars not full (ROS: 40)

    Examples
    --------
    >>> t = CoverageTracker()
    >>> t.ready(), len(t.samples)
    (False, 0)
    """

    def __init__(self, board: Board = DUCKIETOWN_BOARD, image_size=IMAGE_SIZE, *,
                 min_distance: float = SAMPLE_MIN_DISTANCE, param_ranges=PARAM_RANGES,
                 max_samples: int = MAX_SAMPLES_FOR_CALIBRATE):
        if not isinstance(board, Board):
            raise DtscalError(f"board must be a Board, got {type(board).__name__}")
        self.board = board
        self.image_size = as_size(image_size, name="image_size")
        if not (np.isfinite(min_distance) and min_distance >= 0):
            raise DtscalError(f"min_distance must be a non-negative number, got {min_distance!r}")
        ranges = np.asarray(param_ranges, dtype=np.float64).ravel()
        if ranges.shape != (4,) or not np.all(np.isfinite(ranges)) or np.any(ranges <= 0):
            raise DtscalError(f"param_ranges must be 4 positive numbers (X, Y, Size, Skew), got {param_ranges!r}")
        if int(max_samples) != max_samples or max_samples < 1:
            raise DtscalError(f"max_samples must be a positive integer, got {max_samples!r}")
        self.min_distance = float(min_distance)
        self.param_ranges = tuple(float(r) for r in ranges)
        self.max_samples = int(max_samples)
        self.samples: list[Sample] = []
        self.frames_offered = 0

    def __len__(self) -> int:
        return len(self.samples)

    def offer(self, detection_or_corners, frame_index: int | None = None) -> bool:
        """Consider one detection; store it as a sample if it adds coverage.

        Parameters
        ----------
        detection_or_corners : :class:`dtscal_lib.detect.Detection` or (N, 2) corners
            A detection that was not found (no board, at the border) is never a sample.
        frame_index : index recorded with the sample (default: count of offers so far)

        Returns
        -------
        True if it was stored.
        """
        index = self.frames_offered if frame_index is None else int(frame_index)
        self.frames_offered += 1
        corners = self._corners_of(detection_or_corners)
        if corners is None:
            return False
        ids = getattr(detection_or_corners, "ids", None)
        params = board_params(corners, self.board, self.image_size, ids=ids)
        if self.samples:
            nearest = min(param_distance(params, s.params) for s in self.samples)
            if nearest <= self.min_distance:
                return False
        self.samples.append(Sample(corners.copy(), params, index, None if ids is None else np.array(ids)))
        return True

    def _corners_of(self, item) -> np.ndarray | None:
        if hasattr(item, "found") and hasattr(item, "corners"):  # a Detection
            if not item.found:
                return None
            if getattr(item, "board", self.board) != self.board:
                raise DtscalError(
                    f"the detection is for a {item.board.describe()} board but the tracker collects "
                    f"{self.board.describe()}; use one board per session"
                )
            size = getattr(item, "image_size", self.image_size)
            if tuple(size) != self.image_size:
                raise DtscalError(
                    f"the detection comes from a {size[0]}x{size[1]} image but the tracker expects "
                    f"{self.image_size[0]}x{self.image_size[1]}; resize frames to one size per session"
                )
            if getattr(item, "ids", None) is not None:  # a partial ChArUco view
                return as_points(item.corners, 2, "corners")
            return _as_corners(item.corners, self.board)
        return _as_corners(item, self.board)

    def params(self) -> np.ndarray:
        """Parameters of all samples, (n_samples, 4) float64."""
        if not self.samples:
            return np.zeros((0, 4))
        return np.array([s.params for s in self.samples])

    def bars(self) -> list[Bar]:
        """The four bars X, Y, Size, Skew.

        X and Y: ``lo, hi`` = smallest and largest value seen, progress ``(hi - lo) / range``;
        Size and Skew: ``lo = 0`` (small or straight boards earn nothing), ``hi`` = largest
        value seen, progress ``hi / range``. Progress is capped at 1; all zeros without samples.
        """
        p = self.params()
        bars = []
        for k, name in enumerate(PARAM_NAMES):
            if len(p) == 0:
                lo = hi = 0.0
            else:
                hi = float(p[:, k].max())
                lo = float(p[:, k].min()) if k < 2 else 0.0
            progress = min(1.0, (hi - lo) / self.param_ranges[k])
            bars.append(Bar(name, lo, hi, progress, progress >= 1.0))
        return bars

    def ready(self) -> bool:
        """True when CALIBRATE should be enabled: every bar full, or ``max_samples`` samples."""
        if len(self.samples) >= self.max_samples:
            return True
        return bool(self.samples) and all(b.full for b in self.bars())

    def object_and_image_points(self) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Calibration input from the samples.

        Returns
        -------
        object_points : list of (N, 3) float64 board coordinates (one per sample)
        image_points : list of (N, 2) float64 pixels (one per sample)
        """
        obj = self.board.object_points()
        return ([obj.copy() if s.ids is None else obj[s.ids] for s in self.samples],
                [s.corners.copy() for s in self.samples])

    def reset(self) -> None:
        """Forget all samples (start a new session)."""
        self.samples = []
        self.frames_offered = 0
