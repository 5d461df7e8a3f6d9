"""The corners' order: right-handed, rows top to bottom (ROS's rule), square boards included."""

from __future__ import annotations

import numpy as np

from ..boards import DUCKIETOWN_BOARD, Board
from ..errors import DtscalError


def order_corners(corners: np.ndarray, board: Board = DUCKIETOWN_BOARD) -> np.ndarray:
    """Put detected corners in a consistent order: right-handed grid, rows running top to bottom.

    1. Handedness: if the grid appears mirrored (row step x column step < 0 in image
       coordinates, x right and y down), each row is reversed.
    2. ROS's rule: for a non-square board, if the first corner is below the last, the
       whole order is reversed. For a square board ROS rotates the grid until the last
       corner is right of and below the first; so does this function.

    Parameters
    ----------
    corners : (N, 2) pixels in some row-major order of the board

    Returns
    -------
    (N, 2) float64 pixels, a reordered copy
    """
    c = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    if len(c) != board.n_corners:
        raise DtscalError(f"expected {board.n_corners} corners for a {board.describe()} board, got {len(c)}")
    grid = c.reshape(board.rows, board.cols, 2)
    row_step = grid[0, -1] - grid[0, 0]
    col_step = grid[-1, 0] - grid[0, 0]
    if row_step[0] * col_step[1] - row_step[1] * col_step[0] < 0:
        grid = grid[:, ::-1]
    if board.rows != board.cols:
        if grid[0, 0, 1] > grid[-1, -1, 1]:
            grid = grid[::-1, ::-1]
    else:
        # square board: four right-handed orders; choose the one whose diagonal points down-right
        for _ in range(4):
            d = grid[-1, -1] - grid[0, 0]
            if d[0] >= 0 and d[1] >= 0:
                break
            grid = np.rot90(grid)  # a 90-degree turn of the index grid keeps the handedness
        else:
            # no order points down-right (board seen nearly edge-on): use the top-to-bottom rule
            if grid[0, 0, 1] > grid[-1, -1, 1]:
                grid = grid[::-1, ::-1]
    return np.ascontiguousarray(grid.reshape(-1, 2))
