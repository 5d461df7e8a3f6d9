"""Tests for dtscal_lib.coverage: ROS camera_calibration's X / Y / Size / Skew rules."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dtscal_lib.boards import DUCKIETOWN_BOARD, Board
from dtscal_lib.coverage import (
    CoverageTracker,
    board_params,
    outside_corners,
    param_distance,
    quad_area,
    skew_angle,
)
from dtscal_lib.detect import Detection
from dtscal_lib.errors import DtscalError

B = DUCKIETOWN_BOARD
SIZE = (640, 480)


def grid(origin, a, b, board: Board = B) -> np.ndarray:
    """Corners ``origin + i a + j b`` in row-major order: (cols*rows, 2)."""
    j, i = np.mgrid[0:board.rows, 0:board.cols]
    return (np.asarray(origin, float) + i.reshape(-1, 1) * np.asarray(a, float)
            + j.reshape(-1, 1) * np.asarray(b, float))


def centred(spacing=30.0, cx=320.0, cy=240.0):
    return grid((cx - 3 * spacing, cy - 2 * spacing), (spacing, 0), (0, spacing))


# --------------------------------------------------------------------------- board_params
def test_centred_fronto_parallel_board_by_hand():
    # corners span x 230..410, y 180..300: area 180*120 = 21600, border = 146.969
    p = board_params(centred(), B, SIZE)
    border = math.sqrt(21600.0)
    assert p[0] == pytest.approx((320 - border / 2) / (640 - border))
    assert p[0] == pytest.approx(0.5)
    assert p[1] == pytest.approx(0.5)
    assert p[2] == pytest.approx(math.sqrt(21600.0 / (640 * 480)))  # 0.26517
    assert p[2] == pytest.approx(0.26517, abs=1e-5)
    assert p[3] == pytest.approx(0.0, abs=1e-12)


def test_board_at_the_left_and_top_gives_x_and_y_near_zero():
    c = grid((10, 12), (30, 0), (0, 30))  # x 10..190, y 12..132
    p = board_params(c, B, SIZE)
    border = math.sqrt(180 * 120)
    assert p[0] == pytest.approx((100 - border / 2) / (640 - border))  # 0.054
    assert p[0] < 0.06 and p[1] < 0.06
    right = board_params(grid((630 - 180, 470 - 120), (30, 0), (0, 30)), B, SIZE)
    assert right[0] > 0.94 and right[1] > 0.94


def test_clamped_to_unit_interval_and_image_filling_board():
    c = grid((-100, -100), (30, 0), (0, 30))  # partly outside: X would be negative
    assert board_params(c, B, SIZE)[0] == 0.0
    huge = grid((5, 5), (105, 0), (0, 117))  # 630 x 468 quad: border > image height
    p = board_params(huge, B, SIZE)
    assert np.all(np.isfinite(p))
    assert p[1] == 0.5


def test_skew_of_a_sheared_board_by_hand():
    phi = math.radians(100.0)  # column direction leaning left: angle at up_right is 80 degrees
    c = grid((250, 200), (30, 0), (30 * math.cos(phi), 30 * math.sin(phi)))
    assert math.degrees(skew_angle(outside_corners(c, B))) == pytest.approx(80.0)
    assert board_params(c, B, SIZE)[3] == pytest.approx(2 * math.radians(10.0))  # 0.349
    phi = math.radians(130.0)  # 40 degrees off: 2 * 0.698 > 1, capped
    c = grid((300, 200), (30, 0), (30 * math.cos(phi), 30 * math.sin(phi)))
    assert board_params(c, B, SIZE)[3] == 1.0


def test_outer_corner_names_follow_ros():
    c = centred()
    ul, ur, dr, dl = outside_corners(c, B)
    np.testing.assert_allclose([ul, ur, dr, dl], [c[0], c[B.cols - 1], c[-1], c[-B.cols]])
    np.testing.assert_allclose(ul, [230, 180])
    np.testing.assert_allclose(dr, [410, 300])


def test_quad_area_of_a_trapezoid():
    # parallel sides 100 (top) and 200 (bottom), height 50: area 7500
    quad = [[50, 0], [150, 0], [200, 50], [0, 50]]
    assert quad_area(quad) == pytest.approx(7500.0)


def test_bad_corners_are_rejected_with_clear_messages():
    with pytest.raises(DtscalError, match="35, 2"):
        board_params(np.zeros((34, 2)), B, SIZE)
    c = centred()
    c[3, 0] = np.nan
    with pytest.raises(DtscalError, match="NaN"):
        board_params(c, B, SIZE)
    with pytest.raises(DtscalError, match="image_size"):
        board_params(centred(), B, (0, 480))
    degenerate = np.tile([[100.0, 100.0]], (35, 1))
    with pytest.raises(DtscalError, match="degenerate"):
        board_params(degenerate, B, SIZE)


def test_opencv_shaped_corners_are_accepted():
    c = centred()
    np.testing.assert_allclose(board_params(c.reshape(-1, 1, 2).astype(np.float32), B, SIZE),
                               board_params(c, B, SIZE), atol=1e-6)


# --------------------------------------------------------------------------- sample selection
def test_first_sample_always_taken_and_duplicates_refused():
    t = CoverageTracker(B, SIZE)
    assert t.offer(centred()) is True
    assert t.offer(centred()) is False
    assert t.offer(centred() + 3.0) is False  # tiny move: L1 distance far below 0.2
    assert len(t.samples) == 1
    assert t.samples[0].frame_index == 0
    assert t.frames_offered == 3


def test_distance_rule_against_every_stored_sample():
    t = CoverageTracker(B, SIZE)
    base = centred()
    t.offer(base)
    p0 = t.samples[0].params
    # move right until X changes by 0.15 (< 0.2: refused) and by 0.25 (> 0.2: taken)
    span = 640 - math.sqrt(180 * 120)
    near = base + [0.15 * span, 0]
    far = base + [0.25 * span, 0]
    assert param_distance(board_params(near, B, SIZE), p0) == pytest.approx(0.15)
    assert t.offer(near) is False
    assert t.offer(far) is True
    # 0.15 from the second sample but 0.40 from the first: still refused (nearest counts)
    between = base + [0.40 * span, 0]
    assert t.offer(between) is False
    assert t.offer(base + [0.46 * span, 0]) is True


def test_threshold_is_strict_greater_than():
    base = centred()
    # exactly min_distance away (within float rounding): ROS refuses d <= 0.2
    t2 = CoverageTracker(B, SIZE, min_distance=param_distance(board_params(base + [50, 0], B, SIZE),
                                                              board_params(base, B, SIZE)))
    t2.offer(base)
    assert t2.offer(base + [50, 0]) is False


def test_detections_not_found_are_never_samples():
    t = CoverageTracker(B, SIZE)
    assert t.offer(Detection(False, None, "no_board", B, SIZE)) is False
    assert t.offer(Detection(False, centred(), "at_border", B, SIZE)) is False
    assert t.offer(Detection(True, centred(), None, B, SIZE)) is True
    with pytest.raises(DtscalError, match="board"):
        t.offer(Detection(True, centred()[:20], None, Board(5, 4, 0.03), SIZE))
    with pytest.raises(DtscalError, match="1280x960"):
        t.offer(Detection(True, centred(), None, B, (1280, 960)))


# --------------------------------------------------------------------------- bars and ready()
def test_bars_by_hand_for_two_samples():
    t = CoverageTracker(B, SIZE)
    assert [b.progress for b in t.bars()] == [0, 0, 0, 0]
    left = grid((10, 12), (30, 0), (0, 30))
    right = grid((630 - 180, 470 - 120), (30, 0), (0, 30))
    t.offer(left)
    t.offer(right)
    pl, pr = board_params(left, B, SIZE), board_params(right, B, SIZE)
    bars = {b.name: b for b in t.bars()}
    assert bars["X"].lo == pytest.approx(pl[0]) and bars["X"].hi == pytest.approx(pr[0])
    assert bars["X"].progress == pytest.approx(min(1.0, (pr[0] - pl[0]) / 0.7))
    assert bars["X"].full and bars["Y"].full  # spans 0.05 .. 0.95 > 0.7
    assert bars["Size"].lo == 0.0
    assert bars["Size"].progress == pytest.approx(pl[2] / 0.4)  # same size twice: 0.265/0.4
    assert not bars["Size"].full
    assert bars["Skew"].progress == pytest.approx(0.0, abs=1e-9)
    assert not t.ready()


def test_ready_when_all_bars_full():
    t = CoverageTracker(B, SIZE)
    t.offer(grid((10, 12), (30, 0), (0, 30)))
    t.offer(grid((630 - 180, 470 - 120), (30, 0), (0, 30)))
    t.offer(centred(spacing=60))  # big: Size = sqrt(360*240/307200) = 0.53
    phi = math.radians(120.0)
    t.offer(grid((250, 150), (30, 0), (30 * math.cos(phi), 30 * math.sin(phi))))  # Skew 1
    assert all(b.full for b in t.bars())
    assert t.ready()
    assert len(t.samples) == 4


def test_ready_at_forty_samples_even_with_bars_not_full():
    t = CoverageTracker(B, SIZE, min_distance=0.0)
    for k in range(39):
        assert t.offer(centred() + [k * 0.5, 0])
    assert not t.ready()
    assert not any(b.full for b in t.bars())
    assert t.offer(centred() + [39 * 0.5, 0])
    assert len(t.samples) == 40
    assert t.ready()


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(20, 400), st.floats(20, 300), st.floats(8, 40),
                          st.floats(-0.6, 0.6), st.floats(-0.4, 0.4)), min_size=1, max_size=25))
def test_bars_are_monotone_and_bounded(boards):
    t = CoverageTracker(B, SIZE)
    before = [0.0] * 4
    for x, y, s, rot, shear in boards:
        a = s * np.array([math.cos(rot), math.sin(rot)])
        b = s * np.array([-math.sin(rot + shear), math.cos(rot + shear)])
        t.offer(grid((x + 60, y + 60), a, b))
        now = [bar.progress for bar in t.bars()]
        assert all(0.0 <= v <= 1.0 for v in now)
        assert all(n >= p - 1e-12 for n, p in zip(now, before))
        before = now
    # every stored pair is farther apart than the rule allows
    P = t.params()
    for i in range(len(P)):
        for j in range(i):
            assert param_distance(P[i], P[j]) > 0.2


def test_object_and_image_points_match_samples():
    t = CoverageTracker(B, SIZE)
    t.offer(grid((10, 12), (30, 0), (0, 30)))
    t.offer(centred(spacing=60))
    obj, img = t.object_and_image_points()
    assert len(obj) == len(img) == 2
    assert obj[0].shape == (35, 3) and img[0].shape == (35, 2)
    np.testing.assert_allclose(obj[1], B.object_points())
    np.testing.assert_allclose(img[1], centred(spacing=60))
    img[0][:] = 0  # copies: the tracker's samples are unchanged
    assert t.samples[0].corners[0, 0] == 10
    t.reset()
    assert len(t) == 0 and t.object_and_image_points() == ([], [])


def test_tracker_validates_its_settings():
    with pytest.raises(DtscalError, match="param_ranges"):
        CoverageTracker(B, SIZE, param_ranges=(0.7, 0.7, 0.4))
    with pytest.raises(DtscalError, match="max_samples"):
        CoverageTracker(B, SIZE, max_samples=0)
    with pytest.raises(DtscalError, match="min_distance"):
        CoverageTracker(B, SIZE, min_distance=-1)
