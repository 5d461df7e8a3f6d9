"""The experiments of the course notebooks (dtscal_lib.teaching.course.experiments), against expectations computed
here from first principles: a robot camera placed by hand, exact view sets, trigonometry."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from dtscal_lib import camera as cam
from dtscal_lib import duckietown as dt
from dtscal_lib import homography
from dtscal_lib.teaching.course import degradation_experiment, experiments


def _robot_camera(height: float, pitch_deg: float, x: float = 0.06, yaw_deg: float = 0.0):
    """Ground (x forward, y left, z up) -> camera (x right, y down, z ahead), written out by hand."""
    p, y = math.radians(pitch_deg), math.radians(yaw_deg)
    ahead = np.array([math.cos(p) * math.cos(y), math.cos(p) * math.sin(y), -math.sin(p)])
    right = np.array([math.sin(y), -math.cos(y), 0.0])
    down = np.cross(ahead, right)
    R = np.vstack([right, down, ahead])
    C = np.array([x, 0.0, height])
    return R, -R @ C


@pytest.mark.parametrize("height, pitch", [(0.104, 18.0), (0.10, 25.0), (0.2, 40.0), (0.05, 8.0)])
def test_height_and_pitch_come_back_from_the_ground_homography(height, pitch):
    K = dt.default_P()[:, :3]
    R, t = _robot_camera(height, pitch)
    H_img = K @ np.column_stack([R[:, 0], R[:, 1], t])  # ground (x, y, 1) -> pixels
    H_ground = np.linalg.inv(H_img)
    for scale in (1.0, -3.0):  # any scale and sign
        h, p = experiments.camera_height_pitch(H_ground * scale / H_ground[2, 2], K)
        assert h == pytest.approx(height, abs=1e-9) and p == pytest.approx(pitch, abs=1e-7)


def test_duckietowns_default_homography_puts_the_camera_about_10_cm_up():
    h, p = experiments.camera_height_pitch(dt.default_H(), dt.default_P()[:, :3])
    assert 0.09 < h < 0.11 and 15 < p < 35  # Duckietown's shipped default.yaml, a real robot's numbers


def test_yaw_cost_is_the_sideways_arc():
    assert experiments.yaw_cost_mm(2.0, 0.5) == pytest.approx(500 * math.sin(math.radians(2)))
    assert experiments.yaw_cost_mm(0.0, 0.5) == 0.0


def test_normalized_dlt_is_invariant_and_the_unnormalized_is_not():
    rows = experiments.invariance_experiment(homography.estimate_homography, [(0, 1), (1000, 1), (0, 1000)])
    norm = [r["normalized"] for r in rows]
    raw = [r["unnormalized"] for r in rows]
    assert max(norm) - min(norm) < 1e-6 and max(raw) - min(raw) > 0.01
    # 1 px of noise per axis on 35 points: the fit's residual against the NOISY points is about
    # sqrt(2 (1 - 8 / 70)) = 1.33 px RMS, its error against the truth well under that
    assert 0.2 < norm[0] < 1.1
    table = experiments.invariance_table(rows)
    assert len(re.findall(r"^\s+\d", table, re.MULTILINE)) == 3


def test_points_off_the_plane_leave_residuals_that_grow_with_height():
    r = experiments.off_plane_experiment([0.0, 0.005, 0.02])
    assert r[0] < 1e-4 < r[1] < r[2]


def test_dlt_column_range_is_u_times_x():
    lo, hi = experiments.dlt_column_range(1e6)
    assert lo == pytest.approx(1.0) and 1e8 < hi < 1e10


def _rows(H):
    def v(i, j):
        a, b = H[:, i], H[:, j]
        return [a[0] * b[0], a[0] * b[1] + a[1] * b[0], a[1] * b[1], a[2] * b[0] + a[0] * b[2],
                a[2] * b[1] + a[1] * b[2], a[2] * b[2]]
    return np.array([v(0, 1), np.subtract(v(0, 0), v(1, 1))])


def test_degenerate_view_sets_lose_rank_as_the_geometry_says():
    K = dt.default_K()
    assert experiments.degenerate_views(_rows, K, "tilted")["rank"] == 5
    assert experiments.degenerate_views(_rows, K, "tilted", n_views=3)["rank"] == 5
    par = experiments.degenerate_views(_rows, K, "parallel")
    assert par["rank"] == 2  # one orientation: the same two equations every time
    fronto = experiments.degenerate_views(_rows, K, "fronto")
    assert np.abs(fronto["V"][:, 3:]).max() < 1e-12  # h1, h2 at infinity: B13, B23, B33 never appear
    np.testing.assert_allclose(experiments.zhang_constraints(K @ np.eye(3)), _rows(K @ np.eye(3)))
    with pytest.raises(ValueError, match="kind must be"):
        experiments.degenerate_views(_rows, K, "sideways")


def test_field_of_view_of_a_pinhole_is_2_atan():
    K = np.array([[300.0, 0, 320], [0, 300, 240], [0, 0, 1]])
    h, d = experiments.field_of_view(K, np.zeros(5))
    assert h == pytest.approx(math.degrees(math.atan(320 / 300) + math.atan(319 / 300)), abs=1e-6)
    assert d > h
    wide_h, _ = experiments.field_of_view(dt.default_K(), dt.default_dist())
    assert wide_h > 100  # barrel distortion: wider than its pinhole's 2 atan(320 / 308) = 92 deg


def test_corner_shift_and_line_bend():
    K, d = dt.default_K(), dt.default_dist()
    x, y = -K[0, 2] / K[0, 0], -K[1, 2] / K[1, 1]
    r2 = x * x + y * y
    rho = 1 + d[0] * r2 + d[1] * r2 * r2
    assert experiments.corner_shift_px(K, d) == pytest.approx((1 - rho) * math.hypot(K[0, 2], K[1, 2]), rel=0.05)
    assert experiments.line_bend_px(K, d, d[0], d[1]) < 1e-6
    assert experiments.line_bend_px(K, d, 0.0, 0.0) > 5
    assert experiments.line_bend_px(K, d, -0.2, 0.0) < experiments.line_bend_px(K, d, 0.0, 0.0)


def test_fixed_point_converges_slowly_at_the_corners():
    K, d = dt.default_K(), dt.default_dist()
    assert experiments.fixed_point_converged(K, d, 5) <= experiments.fixed_point_converged(K, d, 200) <= 4
    assert experiments.fixed_point_converged(K, np.zeros(5), 1) == 4


def test_span_at_yaw_keeps_the_board_centred():
    project = lambda K, R, t, X: cam.project_points(X, R, t, K)  # noqa: E731
    K = dt.default_K()
    u0, u1 = experiments.span_at_yaw(project, K, 60, distance=0.5)
    s0, s1 = experiments.span_at_yaw(project, K, 0, distance=0.5)
    assert 0 <= s0 < u0 < u1 < s1 <= 640  # narrower, inside


def test_the_shared_configuration_prints_one_number_in_both_tables():
    K = dt.default_K()

    def closed(Hs):
        from dtscal_lib import calibration

        return calibration.zhang_closed_form(Hs, dt.IMAGE_SIZE, skew=True)

    text = degradation_experiment(closed, K, view_counts=(10,), tilts=((20.0, 45.0),), trials=2)
    n10 = re.search(r"^\s+10\s+(\S+)$", text, re.MULTILINE).group(1)
    t = re.search(r"^\s+20-45 deg\s+(\S+)$", text, re.MULTILINE).group(1)
    assert n10 == t


def test_lens_explorer_has_a_fixed_text_form():
    box = experiments.lens_explorer(dt.default_K(), dt.default_dist())
    assert repr(box).startswith("lens explorer: sliders for k1 and k2")


def test_lens_explorer_starts_from_the_students_guess():
    box = experiments.lens_explorer(dt.default_K(), dt.default_dist(), k1=-0.12, k2=0.015)
    k1, k2 = box.children[0], box.children[1]
    assert (k1.value, k2.value) == (-0.12, 0.015)
    assert "bend by" in box.children[3].value


def test_line_bend_scores_what_the_picture_shows():
    """Issue 29: the old number jumped from 12.9 px (k1 -0.20) to 614 px (-0.22) and 809 px (-0.26) on points the
    picture never showed, and rated (-0.26, 0.035), whose lines look straight, worse than no correction."""
    K, d = dt.default_K(), dt.default_dist()
    bend = {(a, b): experiments.line_bend_px(K, d, a, b, step=4)
            for a, b in [(0.0, 0.0), (-0.20, 0.0), (-0.22, 0.0), (-0.26, 0.0), (-0.26, 0.035), (-0.26, 0.045),
                         (-0.24, 0.045), (-0.28, 0.045), (-0.26, 0.06)]}
    assert bend[(-0.26, 0.035)] < bend[(0.0, 0.0)] / 2
    k2_zero = [bend[(a, 0.0)] for a in (-0.20, -0.22, -0.26)]
    assert max(k2_zero) < 3 * min(k2_zero) < 3 * bend[(0.0, 0.0)]  # no jump: the picture degrades gradually
    truth = experiments.line_bend_px(K, d, d[0], d[1], step=4)
    assert truth < 1e-6 and truth < min(bend.values())  # straight lines score best
    near = bend[(-0.26, 0.045)]  # 0.003 from the truth: nearly straight
    assert near < min(bend[(-0.24, 0.045)], bend[(-0.28, 0.045)], bend[(-0.26, 0.06)])


def test_the_games_lens_is_straightened_by_its_own_coefficients_only():
    K, lens = dt.default_K(), experiments.mystery_lens()
    assert experiments.line_bend_px(K, lens, lens[0], lens[1], step=4) < 1e-6
    assert experiments.line_bend_px(K, lens, *dt.default_dist()[:2], step=4) > 0.5  # not the recorded camera's


def test_pitch_cost_follows_the_ray_geometry():
    h, x = 0.104, 0.5
    want = 1000 * (h / math.tan(math.atan(h / x) - math.radians(1.0)) - x)  # the same ray, 1 deg flatter
    assert experiments.pitch_cost_mm(1.0, x, h) == pytest.approx(want)
    assert experiments.pitch_cost_mm(0.0, x, h) == pytest.approx(0.0, abs=1e-9)
    assert experiments.pitch_cost_mm(20.0, x, h) == math.inf  # the ray above the horizon never meets the ground
    assert experiments.pitch_cost_mm(1.0, 0.8, h) > 2 * experiments.pitch_cost_mm(1.0, 0.5, h)
