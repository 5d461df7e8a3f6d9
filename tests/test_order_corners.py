"""The corners' order of a square board seen nearly edge-on (issue 21's planted bug: its fallback dropped).

ROS's ``camera_calibration`` orders a detection top to bottom: if the first corner is below the last, the order
is reversed (``duckietown.md``, "corners reordered to run top to bottom"). For a square board the kit first turns
the grid until its diagonal points down-right; a board seen so nearly edge-on that no turn does (both diagonals
point up-right or down-left) falls back to ROS's top-to-bottom rule. The grids here are built by hand: a 5x5
board whose rows step by ``u`` and columns by ``v``, with ``u + v`` and ``u - v`` both pointing up-right.
"""

from __future__ import annotations

import numpy as np
import pytest

from dtscal_lib.boards import Board
from dtscal_lib.detect import order_corners

SQUARE = Board(5, 5, 0.03)


def edge_on_grid(u=(5.5, -5.5), v=(1.5, 1.5), origin=(200.0, 200.0)) -> np.ndarray:
    j, i = np.mgrid[0:5, 0:5]
    return np.asarray(origin) + i[..., None] * np.asarray(u) + j[..., None] * np.asarray(v)  # (rows, cols, 2)


def handedness(c: np.ndarray) -> float:
    g = c.reshape(5, 5, 2)
    a, b = g[0, -1] - g[0, 0], g[-1, 0] - g[0, 0]
    return float(a[0] * b[1] - a[1] * b[0])


@pytest.mark.parametrize("turns", [0, 1, 2, 3])
@pytest.mark.parametrize("mirrored", [False, True])
def test_square_board_seen_edge_on_runs_top_to_bottom(turns, mirrored):
    g = np.rot90(edge_on_grid(), turns)
    if mirrored:
        g = g[:, ::-1]
    # no turn of this grid has its diagonal pointing down-right: the fallback is what decides
    diagonals = [np.rot90(g, k)[-1, -1] - np.rot90(g, k)[0, 0] for k in range(4)]
    assert not any(d[0] >= 0 and d[1] >= 0 for d in diagonals)
    out = order_corners(g.reshape(-1, 2), SQUARE)
    assert out[0, 1] <= out[-1, 1], "the first corner must not be below the last (ROS's top-to-bottom rule)"
    assert handedness(out) > 0
    assert sorted(map(tuple, out)) == sorted(map(tuple, g.reshape(-1, 2)))  # the same corners, reordered

