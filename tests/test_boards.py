import numpy as np
import pytest

from dtscal_lib import duckietown as dt
from dtscal_lib.boards import DUCKIETOWN_BOARD, Board, ground_points, order_for_ground, parse_board
from dtscal_lib.errors import DtscalError


def test_duckietown_board_geometry():
    b = DUCKIETOWN_BOARD
    assert (b.cols, b.rows, b.square) == (7, 5, 0.031)
    obj = b.object_points()
    assert obj.shape == (35, 3)
    assert np.all(obj[:, 2] == 0)
    # row-major: second corner is one square to the right, corner `cols` one square down
    np.testing.assert_allclose(obj[1] - obj[0], [0.031, 0, 0])
    np.testing.assert_allclose(obj[7] - obj[0], [0, 0.031, 0])
    assert b.outer_corner_indices() == (0, 6, 34, 28)


@pytest.mark.parametrize("spec,cols,rows", [("7x5", 7, 5), ("9X6", 9, 6), (" 4 x 3 ", 4, 3)])
def test_parse_board(spec, cols, rows):
    b = parse_board(spec, 0.02)
    assert (b.cols, b.rows, b.square) == (cols, rows, 0.02)


@pytest.mark.parametrize("spec", ["7", "7x", "ax5", "7x5x3", ""])
def test_parse_board_rejects(spec):
    with pytest.raises(DtscalError, match="CxR"):
        parse_board(spec)


@pytest.mark.parametrize("kw", [dict(cols=1, rows=5), dict(cols=7, rows=5, square=0),
                                dict(cols=7, rows=5, square=float("nan"))])
def test_board_rejects_nonsense(kw):
    with pytest.raises(DtscalError):
        Board(**kw)


def test_ground_points_match_duckietown_placement():
    g = ground_points()
    assert g.shape == (35, 2)
    # near row at x = 0.191, corners from y = -0.093 to +0.093, first point near-right
    np.testing.assert_allclose(g[0], [0.191, -0.093], atol=1e-12)
    np.testing.assert_allclose(g[6], [0.191, 0.093], atol=1e-12)
    np.testing.assert_allclose(g[:, 0].min(), 0.191)
    np.testing.assert_allclose(g[:, 0].max(), 0.191 + 4 * 0.031)
    # the printed board's outer corner is one square outside the inner-corner grid
    np.testing.assert_allclose([g[:, 0].min() - 0.031, g[:, 1].min() - 0.031], [0.160, -0.124], atol=1e-12)
    k = np.arange(35)  # every corner: point k = (x0 + (k // cols) * square, y0 + (k % cols) * square)
    np.testing.assert_allclose(g, np.column_stack([0.191 + (k // 7) * 0.031, -0.093 + (k % 7) * 0.031]), atol=1e-12)


def _fake_image_of_ground_board():
    """Image points of a board ahead of the robot: near row at the bottom, robot's right = image right."""
    g = ground_points()
    u = 320 - g[:, 1] * 1000  # y left -> image left
    v = 480 - (g[:, 0] - 0.1) * 1000  # farther -> higher up
    return np.column_stack([u, v])


@pytest.mark.parametrize("flip", ["none", "rot180", "rows", "cols"])
def test_order_for_ground_recovers_ground_order(flip):
    pts = _fake_image_of_ground_board()
    grid = pts.reshape(5, 7, 2)
    shuffled = {"none": grid, "rot180": grid[::-1, ::-1], "rows": grid[::-1], "cols": grid[:, ::-1]}[flip]
    ordered = order_for_ground(shuffled.reshape(-1, 2))
    np.testing.assert_allclose(ordered, pts)


def test_order_for_ground_wrong_count():
    with pytest.raises(DtscalError, match="expected 35 corners"):
        order_for_ground(np.zeros((30, 2)))


def test_duckietown_facts_are_consistent():
    K = dt.default_K()
    assert K.shape == (3, 3) and K[0, 0] == pytest.approx(307.7379294605756)
    assert dt.default_dist().shape == (5,)
    assert dt.default_P().shape == (3, 4)
    assert not dt.homography_is_corrupt(dt.default_H())
    bad = dt.default_H().copy()
    bad[1, 2] = 0.1
    assert dt.homography_is_corrupt(bad)
