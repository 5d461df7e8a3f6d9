"""Checks of options and arguments at the boundary, before any work is done.

The calibration entry points (:mod:`dtscal_lib.pipeline`, the ``dtscal`` command) call
these first, so that a mistyped option costs a clear message instead of a traceback,
or a wrong calibration, after minutes of frame decoding. Each message names the
command-line flag and the library argument, says what was wrong and what to give.

>>> board_from_flags("7x5", 0.031).describe()
'7x5 inner corners, 31 mm squares'
>>> check_image_size((640, 480))
(640, 480)
"""

from __future__ import annotations

import numbers
import os
import tempfile
from pathlib import Path

import numpy as np

from .boards import Board, CharucoBoard, parse_board
from .errors import DtscalError

__all__ = ["IMAGE_SIDE_RANGE", "MAX_CORNERS", "MIN_CORNERS", "SQUARE_RANGE_M", "board_from_flags", "check_board",
           "check_image_size", "check_output_folder", "check_seed", "parse_board"]

#: OpenCV's chessboard detector needs more than 2 inner corners per side
MIN_CORNERS = 3
#: more inner corners per side than any printable calibration board has
MAX_CORNERS = 100
#: a printed square from 2 mm (a phone screen) to 0.5 m (a wall poster), in metres
SQUARE_RANGE_M = (0.002, 0.5)
#: image sides (pixels) a calibration can work with: a board of 3x3 corners needs tens of
#: pixels; the upper bound is that of the guarded decoder (far below OpenCV's own)
IMAGE_SIDE_RANGE = (32, 16384)


def check_board(board: Board) -> Board:
    """A calibration board in metres that the detector and the optimiser can use.

    Raises
    ------
    DtscalError
        Fewer than 3 or more than 100 inner corners per side (``--board CxR``), or a
        square outside 2 mm .. 0.5 m (``--square``; a square of 1e-200 or 1e300 m makes
        the numbers meaningless long before the optimiser notices).
    """
    if not isinstance(board, Board):
        raise DtscalError(f"board must be a dtscal_lib.boards.Board, got {type(board).__name__}")
    for n in (board.cols, board.rows):
        if not MIN_CORNERS <= n <= MAX_CORNERS:
            raise DtscalError(
                f"--board {board.cols}x{board.rows}: a calibration board needs {MIN_CORNERS} to {MAX_CORNERS} "
                "inner corners per side (count where four squares meet; Duckietown's board is 7x5)"
            )
    lo, hi = SQUARE_RANGE_M
    sq = float(board.square)
    if not (np.isfinite(sq) and lo <= sq <= hi):
        raise DtscalError(
            f"--square {board.square!r}: the square size is in metres and must be between {lo:g} and {hi:g} "
            "(Duckietown's board has 0.031 m squares); measure one square of the printed board"
        )
    return board


def board_from_flags(spec: str, square: float) -> Board:
    """The board of ``--board CxR --square S``, checked (:func:`check_board`); messages name the flags."""
    lo, hi = SQUARE_RANGE_M
    if not (isinstance(square, (int, float)) and np.isfinite(square) and lo <= square <= hi):
        raise DtscalError(
            f"--square {square!r}: the square size is in metres and must be between {lo:g} and {hi:g} "
            "(Duckietown's board has 0.031 m squares); measure one square of the printed board"
        )
    try:
        board = parse_board(spec, square)
    except DtscalError as e:
        raise DtscalError(f"--board {spec}: {e}") from None
    return check_board(board)


def charuco_from_flags(squares: str, square: float, marker, dictionary: str, legacy: bool) -> CharucoBoard:
    """The board of ``--charuco SXxSY --square S --marker M --aruco-dict D [--legacy]``, checked."""

    try:
        sx, sy = parse_board(squares, 1.0).pattern_size
    except DtscalError:
        raise DtscalError(f"--charuco {squares}: give the printed squares as SXxSY, e.g. --charuco 8x6") from None
    if marker is None:
        raise DtscalError("--charuco needs --marker: the side of one ArUco marker in metres (measure its black "
                          "border on the print; calib.io prints it on the board)")
    board_from_flags(f"{sx - 1}x{sy - 1}", square)  # the same limits as a chessboard's inner corners and squares
    try:
        return CharucoBoard.from_squares(sx, sy, square, float(marker), dictionary, legacy)
    except DtscalError as e:
        raise DtscalError(f"--charuco {squares}: {e}") from None


def check_image_size(size, *, name: str = "image_size", hint: str = "") -> tuple[int, int]:
    """``(width, height)`` as two integers within :data:`IMAGE_SIDE_RANGE`.

    Booleans and non-integral numbers are refused (``(True, 480)`` is not a width).
    ``hint`` is appended to the message (where to fix the size).
    """
    try:
        w, h = size
    except (TypeError, ValueError):
        raise DtscalError(f"{name} must be (width, height) in pixels, e.g. (640, 480); got {size!r}") from None
    lo, hi = IMAGE_SIDE_RANGE
    out = []
    for v in (w, h):
        ok = isinstance(v, numbers.Integral) and not isinstance(v, (bool, np.bool_))
        if not ok and isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_)):
            ok = bool(np.isfinite(v)) and float(v).is_integer()
        if not ok:
            raise DtscalError(f"{name} must be two whole numbers of pixels (width, height), got {size!r}")
        if int(v) <= 0:
            raise DtscalError(f"{name} must be positive (width, height) in pixels, got {size!r}" + hint)
        if not lo <= int(v) <= hi:
            raise DtscalError(
                f"{name} {size!r}: each side must be {lo} to {hi} pixels (a Duckiebot camera gives 640x480)"
                + hint
            )
        out.append(int(v))
    return out[0], out[1]


def check_seed(seed) -> int | None:
    """A random seed for ``--seed``: ``None`` or an integer 0 .. 2**63 - 1."""
    if seed is None:
        return None
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or not 0 <= int(seed) < 2**63:
        raise DtscalError(f"--seed {seed!r}: give a whole number from 0 to 2**63 - 1 (or leave it out)")
    return int(seed)


def check_output_folder(path, *, flag: str = "--out") -> Path:
    """A folder that exists (it is created) and can be written to; returns it.

    Proven by creating and removing a probe file, which also works for root on a
    read-only mount, where permission bits say nothing.
    """
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise DtscalError(f"{flag} {str(p)!r} is a file, not a folder; give a folder to write into")
    try:
        p.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".dtscal-probe.", dir=p)
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise DtscalError(f"{flag} {str(p)!r} cannot be written to ({e.strerror or e}); "
                          "choose a folder you can write to") from None
    return p
