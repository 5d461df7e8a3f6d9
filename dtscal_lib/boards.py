"""Calibration boards: geometry, the Duckietown board and its ground placement.

Object points are in the board frame: x to the right along a row of inner corners,
y down the columns, z = 0 on the board, in the unit of ``square`` (metres for the
Duckietown board). Corner order is OpenCV's: row by row, ``cols`` corners per row.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from .errors import DtscalError


@dataclass(frozen=True)
class Board:
    """A checkerboard described by its inner corners.

    Parameters
    ----------
    cols, rows : int
        Inner corners per row and per column (OpenCV's ``patternSize = (cols, rows)``).
        The board has ``cols + 1`` by ``rows + 1`` squares.
    square : float
        Side of one square, in any unit (the object points come out in it).

    Examples
    --------
    >>> b = Board(7, 5, 0.031)
    >>> b.object_points().shape
    (35, 3)
    """

    cols: int = 7
    rows: int = 5
    square: float = 0.031

    def __post_init__(self):
        if int(self.cols) != self.cols or int(self.rows) != self.rows or self.cols < 2 or self.rows < 2:
            raise DtscalError(
                f"a board needs at least 2x2 inner corners, got {self.cols}x{self.rows}; "
                "count the inner corners (where four squares meet), e.g. --board 7x5"
            )
        if not (np.isfinite(self.square) and self.square > 0):
            raise DtscalError(f"square size must be a positive number, got {self.square!r}")

    @property
    def pattern_size(self) -> tuple[int, int]:
        """``(cols, rows)``, as OpenCV's detectors take it."""
        return (int(self.cols), int(self.rows))

    @property
    def n_corners(self) -> int:
        return int(self.cols * self.rows)

    def object_points(self) -> np.ndarray:
        """Inner-corner coordinates on the board plane, (N, 3) float64, z = 0, row-major."""
        j, i = np.mgrid[0 : self.rows, 0 : self.cols]
        pts = np.zeros((self.n_corners, 3), dtype=np.float64)
        pts[:, 0] = i.ravel() * self.square
        pts[:, 1] = j.ravel() * self.square
        return pts

    @property
    def centre(self) -> np.ndarray:
        """The centre of the inner-corner grid, (3,) float64 board coordinates (z = 0)."""
        return np.array([(self.cols - 1) * self.square / 2, (self.rows - 1) * self.square / 2, 0.0])

    def outer_corner_indices(self) -> tuple[int, int, int, int]:
        """Indices of the grid's four outer corners: (top-left, top-right, bottom-right, bottom-left)."""
        c, r = self.cols, self.rows
        return (0, c - 1, c * r - 1, c * (r - 1))

    def describe(self) -> str:
        return f"{self.cols}x{self.rows} inner corners, {self.square * 1000:g} mm squares"



#: ArUco dictionaries by the names ROS's ``cameracalibrator.py --aruco_dict`` takes (image_pipeline,
#: camera_calibration/src/camera_calibration/calibrator.py, ``ChessboardInfo``), mapped to OpenCV's constants
ARUCO_DICTIONARIES = {
    "aruco_orig": "DICT_ARUCO_ORIGINAL",
    **{f"{b}x{b}_{n}": f"DICT_{b}X{b}_{n}" for b in (4, 5, 6, 7) for n in (50, 100, 250, 1000)},
}


@dataclass(frozen=True)
class CharucoBoard(Board):
    """A ChArUco board: a chessboard whose white squares hold ArUco markers, so a part of it is enough.

    Described as it is printed and sold (calib.io, OpenCV's ``CharucoBoard``, ROS's calibrator with
    ``--pattern charuco``): ``squares_x`` by ``squares_y`` squares of side ``square``, markers of side
    ``marker`` from the ArUco dictionary ``dictionary`` (ROS's names, :data:`ARUCO_DICTIONARIES`), and
    ``legacy`` for boards laid out before OpenCV 4.6 (calib.io's "OpenCV <= 4.5" switch: with an even
    number of rows the first marker then sits in the other corner square).

    The chessboard's inner corners are the calibration points: ``cols = squares_x - 1`` by
    ``rows = squares_y - 1``, numbered as OpenCV numbers them (ChArUco id ``k`` is row ``k // cols``,
    column ``k % cols``), so :meth:`object_points` indexed by the detected ids gives each corner's board
    coordinate. Unlike a chessboard, a view may hold any subset of them.

    >>> b = CharucoBoard.from_squares(8, 6, 0.03, 0.022, "5x5_100")
    >>> (b.cols, b.rows, b.n_corners)
    (7, 5, 35)
    """

    marker: float = 0.0
    dictionary: str = "5x5_100"
    legacy: bool = False

    @classmethod
    def from_squares(cls, squares_x: int, squares_y: int, square: float, marker: float,
                     dictionary: str = "5x5_100", legacy: bool = False) -> "CharucoBoard":
        """The board as printed: squares across and down, square and marker sides (metres)."""
        return cls(int(squares_x) - 1, int(squares_y) - 1, float(square), float(marker), str(dictionary),
                   bool(legacy))

    def __post_init__(self):
        super().__post_init__()
        if self.dictionary not in ARUCO_DICTIONARIES:
            raise DtscalError(f"unknown ArUco dictionary {self.dictionary!r}; use one of ROS's names: "
                              + ", ".join(ARUCO_DICTIONARIES) + " (printed on a calib.io board as e.g. DICT_5X5)")
        if not (np.isfinite(self.marker) and 0 < self.marker < self.square):
            raise DtscalError(f"the marker side must be positive and smaller than the square ({self.square:g}); "
                              f"got {self.marker!r}: measure one ArUco marker's black border on the print")

    @property
    def squares(self) -> tuple[int, int]:
        """``(squares_x, squares_y)``: the printed squares across and down."""
        return (int(self.cols) + 1, int(self.rows) + 1)

    def opencv_board(self):
        """OpenCV's ``cv2.aruco.CharucoBoard`` of this board (legacy layout set when asked)."""
        return _opencv_charuco(self.squares, float(self.square), float(self.marker), self.dictionary,
                               bool(self.legacy))

    def describe(self) -> str:
        sx, sy = self.squares
        return (f"ChArUco {sx}x{sy} squares ({self.cols}x{self.rows} inner corners), {self.square * 1000:g} mm "
                f"squares, {self.marker * 1000:g} mm {self.dictionary} markers"
                + (", legacy layout" if self.legacy else ""))


def _opencv_charuco(squares, square, marker, dictionary, legacy):
    import cv2  # the board model stays importable without OpenCV's aruco module loaded

    key = (tuple(squares), square, marker, dictionary, legacy)
    board = _CHARUCO_CACHE.get(key)
    if board is None:
        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, ARUCO_DICTIONARIES[dictionary]))
        board = cv2.aruco.CharucoBoard(tuple(squares), square, marker, d)
        board.setLegacyPattern(bool(legacy))
        _CHARUCO_CACHE[key] = board
    return board


_CHARUCO_CACHE: dict = {}

#: the Duckietown calibration board: 8x6 squares, 7x5 inner corners, 31 mm squares (``dts duckiebot
#: calibrate_intrinsics`` runs ROS's calibrator with ``--size 7x5 --square 0.031``; lib-dt-computer-vision's
#: boards.py ``CalibrationBoard8by6``)
DUCKIETOWN_BOARD = Board(7, 5, 0.031)


def parse_board(spec: str, square: float | None = None) -> Board:
    """Parse ``"CxR"`` (inner corners) into a :class:`Board`.

    >>> parse_board("9x6", 0.025)
    Board(cols=9, rows=6, square=0.025)
    """
    m = re.fullmatch(r"\s*(\d+)\s*[xX*]\s*(\d+)\s*", str(spec))
    if not m:
        raise DtscalError(f"board must be given as CxR inner corners, e.g. 7x5; got {spec!r}")
    return Board(int(m.group(1)), int(m.group(2)), DUCKIETOWN_BOARD.square if square is None else float(square))


# --- Ground placement for extrinsic calibration -------------------------------------------
# Source: Duckietown's lib-dt-computer-vision, src/dt_computer_vision/camera/calibration/extrinsics/boards.py,
# CalibrationBoard8by6 (7x5 inner corners, square 0.031, x_offset 0.16, y_offset -0.124: the board's outer
# corner, as the printed A3 pattern states it, duckietown.md); the inner corners start one square inside it.
# The DD24's placement is in dtscal_lib.profiles.
#: x (forward, metres) of the board's nearest row of inner corners (0.160 + 0.031)
GROUND_NEAR_ROW_X = 0.191
#: |y| (metres) of the outermost inner-corner columns (corners span -0.093 .. +0.093; -0.124 + 0.031)
GROUND_HALF_WIDTH_Y = 0.093


def ground_points(board: Board = DUCKIETOWN_BOARD, x0: float = GROUND_NEAR_ROW_X,
                  y0: float | None = None) -> np.ndarray:
    """Ground coordinates (robot frame, metres: x forward, y left) of the inner corners.

    The board lies flat in front of the robot with its ``cols`` axis across the robot's
    view and its ``rows`` going away. Points are ordered as the Duckietown extrinsic
    procedure orders the detection: starting at the **near-right** corner
    (smallest x, most negative y), running to the left along the near row, then row by
    row away from the robot.

    Parameters
    ----------
    x0 : float
        x of the near row of inner corners.
    y0 : float, optional
        y of the right-most column (default: centred, ``-(cols-1)*square/2``,
        i.e. -0.093 m for the Duckietown board).

    Returns
    -------
    (cols*rows, 2) float64
    """
    if y0 is None:
        y0 = -(board.cols - 1) * board.square / 2.0
    j, i = np.mgrid[0 : board.rows, 0 : board.cols]
    pts = np.empty((board.n_corners, 2), dtype=np.float64)
    pts[:, 0] = x0 + j.ravel() * board.square
    pts[:, 1] = y0 + i.ravel() * board.square
    return pts


def order_for_ground(image_points: np.ndarray, board: Board = DUCKIETOWN_BOARD) -> np.ndarray:
    """Reorder detected corners of a board lying in front of the robot to match :func:`ground_points`.

    On the (rectified) image of a board lying ahead of the robot, the near row is the
    bottom of the board in the image and the robot's right is the image's right. The
    ground order starts at the near-right corner and runs leftward along the near row.
    Whatever order the detector returned (OpenCV may start at any of the four ends), this
    picks the one of the four grid traversals whose first corner is the bottom-right
    and whose first step goes left.

    Parameters
    ----------
    image_points : (cols*rows, 2) pixels, in a detector's row-major order.

    Returns
    -------
    (cols*rows, 2) pixels in ground order.
    """
    pts = np.asarray(image_points, dtype=np.float64).reshape(-1, 2)
    if len(pts) != board.n_corners:
        raise DtscalError(f"expected {board.n_corners} corners for a {board.describe()} board, got {len(pts)}")
    grid = pts.reshape(board.rows, board.cols, 2)
    best, best_score = None, None
    for cand in (grid, grid[::-1, ::-1], grid[::-1, :], grid[:, ::-1]):
        first = cand[0, 0]
        step_row = cand[0, 1] - cand[0, 0]   # along the near row: should go left (-u)
        step_away = cand[1, 0] - cand[0, 0]  # away from the robot: should go up (-v)
        score = first[1] + first[0] - step_row[0] - step_away[1]
        if step_row[0] < 0 and step_away[1] < 0 and (best_score is None or score > best_score):
            best, best_score = cand, score
    if best is None:
        raise DtscalError(
            "could not order the board corners for the ground placement: the board does not "
            "appear to lie ahead of the robot with its long side across the view"
        )
    return best.reshape(-1, 2).copy()
