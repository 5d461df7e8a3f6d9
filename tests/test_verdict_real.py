"""The verdict on real photographs and on planted defects (issue 21): who is blamed for a residual.

Material: OpenCV's real sample photographs (data/real/opencv-samples, 13 views per camera, 9x6
corners, 30 mm), whose residuals are 1.7-2.0x the model-free corner noise; synthetic views of the
Duckietown board through a known camera. Expectations are computed here, independently of the code
under test: the board warp from mrcal's own formula (``mrcal.ref_calibration_object``:
``z = warp * 4 xr (1 - xr)``), the residual sigma from the residuals and the parameter count, the
severities from the rows of dtscal_lib.limits.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from dtscal_lib import camera, duckietown as dt, limits, pipeline, quality
from dtscal_lib.boards import DUCKIETOWN_BOARD, parse_board
from dtscal_lib.calibration import calibrate
from dtscal_lib.richer import fit_richer
from dtscal_lib.session import assess_quality, calibrate_without_outlier_views

REAL = Path(__file__).resolve().parents[1] / "data" / "real" / "opencv-samples"
BOARD = parse_board("9x6", 0.03)
OBJ = DUCKIETOWN_BOARD.object_points()
LENS_WORDS = ("richer lens model", "--model plumb_bob", "estimate k3")


@pytest.fixture(scope="module", params=["left", "right"])
def real(request):
    return request.param, pipeline.calibrate_intrinsics(REAL / request.param, board=BOARD).result


def _views(n, rng, dist, noise=0.05):
    img = []
    while len(img) < n:
        r = [*rng.uniform(-0.5, 0.5, 2), rng.uniform(-0.3, 0.3)]
        t = [rng.uniform(-0.25, 0.05), rng.uniform(-0.17, 0.0), rng.uniform(0.22, 0.35)]
        p = camera.project_points(OBJ, r, t, dt.default_K(), dist)
        if p.min() > 5 and p[:, 0].max() < 635 and p[:, 1].max() < 475:
            img.append(p + rng.normal(0.0, noise, p.shape))
    return [OBJ] * n, img


def _sigma_per_coordinate(res) -> float:
    e = np.concatenate(quality.residuals(res))
    p = len(res.std) + 6 * res.n_views
    return float(np.sqrt((e ** 2).sum() / (e.size - p)))


def test_clean_real_photographs_are_not_bad_and_get_no_lens_advice(real):
    side, res = real
    q = res.quality()
    assert q.verdict != "bad", (side, q.warnings())
    codes = [f.code for f in q.findings]
    assert "fit" not in codes and "unexplained_fit" not in codes, (side, q.warnings())
    for f in q.findings:
        assert not any(w in f.advice for w in LENS_WORDS), (side, str(f))
    # the residual above the noise is said to be the print and the detector, with the warp in mm
    ratio = _sigma_per_coordinate(res) / q.noise_sigma
    assert 1.5 < ratio < limits.LIMITS["unexplained_ratio_doubtful"].value, (side, ratio)
    note = next(n for n in q.notes if n.code == "unexplained_fit")
    assert "mm" in note.message and "the print and the detector" in note.message and "cm" in note.message
    assert f"{ratio:.1f} times" in note.message
    assert "not the lens" not in q.meaning() or "richer lens model" not in q.meaning()


@pytest.mark.parametrize("n_views", [12, 5, 4])
def test_board_warp_is_recovered_as_mrcal_defines_it(n_views):
    """Views of a board bent by 1.5 mm along x and -0.8 mm along y (mrcal's parabola, written out here), named
    from 12 views and from 4-5 too (issue 31: the check used to be skipped below 6 views)."""
    rng = np.random.default_rng(3)
    W, H = 7, 5
    obj = np.array([[i * 0.031, j * 0.031] for j in range(H) for i in range(W)])
    xr, yr = obj[:, 0] / obj[:, 0].max(), obj[:, 1] / obj[:, 1].max()
    z = 0.0015 * 4 * xr * (1 - xr) - 0.0008 * 4 * yr * (1 - yr)
    P = np.column_stack([obj, z])
    img = []
    while len(img) < n_views:
        r = np.array([*rng.uniform(-0.5, 0.5, 2), rng.uniform(-0.3, 0.3)])
        t = np.array([rng.uniform(-0.15, 0.0), rng.uniform(-0.1, 0.0), rng.uniform(0.25, 0.35)])
        p = cv2.projectPoints(P, r, t, dt.default_K(), dt.default_dist())[0].reshape(-1, 2)
        if p.min() > 5 and p[:, 0].max() < 635 and p[:, 1].max() < 475:
            img.append(p + rng.normal(0, 0.02, p.shape))
    res = calibrate([obj] * n_views, img, dt.IMAGE_SIZE)
    w = fit_richer(res, "warp").warp * 1000
    assert w == pytest.approx([1.5, -0.8], abs=0.1), w
    q = res.quality()
    f = next(f for f in q.findings if f.code == "board_warp")
    assert "+1.5" in f.message and "flat" in f.advice, str(f)


def test_a_single_displaced_corner_is_named_left_out_and_recalibrated(real):
    """Corner 21 of view 3 moved by 2 px: off the grid's diagonal (column 3, row 2 of the 9x6 board, rows of 9), so
    a column and a row swapped in the words would show (issue 31)."""
    side, res = real
    img = [np.asarray(p, float).reshape(-1, 2).copy() for p in res.image_points]
    img[3][21] += [2.0 / np.sqrt(2), 2.0 / np.sqrt(2)]  # 2 px
    planted = res.refit(res.object_points, img)
    q = planted.quality()
    assert q.verdict in ("doubtful", "bad")
    f = next(f for f in q.findings if f.code == "outlier_corners")
    assert f.views == [3] and "view 3 corner 21 (column 3, row 2)" in f.message, str(f)
    again = q.without_outlier_corners
    assert again.n_points == planted.n_points - 1
    # without it, the calibration is the clean one again (the planted corner was its only change)
    assert again.rms == pytest.approx(res.rms * np.sqrt(res.n_points / again.n_points), rel=0.02)
    assert abs(again.K[0, 0] - res.K[0, 0]) < 0.1 * res.std["fx"]
    # and the clean set names no corner
    assert not any(f.code == "outlier_corners" for f in res.quality().findings)
    # what the command line and the live CALIBRATE run: the corner is left out of the calibration they keep
    kept, dropped = calibrate_without_outlier_views(res.object_points, img, res.image_size, model=res.model)
    assert dropped == [] and kept.n_points == planted.n_points - 1
    assert [(c["view"], c["corner"], c["column"], c["row"]) for c in kept.left_out_corners] == [(3, 21, 3, 2)]
    np.testing.assert_allclose(kept.K, again.K, rtol=1e-6)
    f = next(f for f in kept.quality().findings if f.code == "outlier_corners")
    assert "left out" in f.message and "view 3 corner 21 (column 3, row 2)" in f.message, str(f)


def test_a_shifted_part_of_a_view_is_named_with_its_view(real):
    """The rows of view 5 below row 2 moved 0.6 px to the right (about 9x the corner noise; a detector that jumped,
    a torn frame): named as a shifted part of view 5, with the step's size and where; the clean set names none.
    What it costs the robot decides "bad" (rules._robot_cost): leaving the view out moves the robot's view little."""
    side, res = real
    assert not any(f.code == "shifted_part" for f in res.quality().findings)
    img = [np.asarray(p, float).reshape(-1, 2).copy() for p in res.image_points]
    lower = np.arange(len(img[5])) >= 3 * 9  # rows 3-5 of the 9x6 board (rows of 9 corners)
    img[5][lower, 0] += 0.6
    q = res.refit(res.object_points, img).quality()
    f = next(f for f in q.findings if f.code == "shifted_part")
    assert f.views == [5] and "rows after row 2 are shifted by" in f.message, str(f)
    size = float(f.message.split("shifted by ")[1].split(" px")[0])
    assert 0.45 < size < 0.75, size  # the step as planted, less what the view's pose absorbs
    assert f.severity == "doubtful" and "robot looks" in f.message and "drop view 5" in f.advice


def test_planted_defects_on_real_photographs_are_named(real):
    side, res = real
    obj = [np.asarray(o, float) for o in res.object_points]
    img = [np.asarray(p, float).reshape(-1, 2).copy() for p in res.image_points]
    # a shifted view: one view's corners all moved by random noise of 1 px
    rng = np.random.default_rng(1)
    bad = [p.copy() for p in img]
    bad[5] = bad[5] + rng.normal(0, 1.0, bad[5].shape)
    q = res.refit(obj, bad).quality()
    assert q.verdict in ("doubtful", "bad") and 5 in q.views_to_drop(), q.warnings()
    # too few views
    q = res.refit(obj[:4], img[:4]).quality()
    assert q.verdict in ("doubtful", "bad") and "few_views" in [f.code for f in q.findings]


def test_the_lens_is_blamed_with_its_own_limits():
    """A lens with k3 fitted without k3: the finding ``fit`` names k3; "bad" above fit_ratio_bad, the fit's own row."""
    rng = np.random.default_rng(2)
    obj, img = _views(16, rng, [-0.25, 0.04, 0.0, 0.0, 0.25])
    res = calibrate(obj, img, dt.IMAGE_SIZE)
    q = res.quality()
    ratio = _sigma_per_coordinate(res) / q.noise_sigma
    f = next(f for f in q.findings if f.code == "fit")
    assert limits.LIMITS["fit_ratio_bad"].value < ratio < 4.0, ratio  # k3 = 0.25: 3.4x (fit_ratio_bad's data)
    assert f.severity == "bad" and "k3" in f.advice, (ratio, str(f))
    assert f"{ratio:.1f} times" in f.message


def test_the_fit_rule_compares_sigma_per_coordinate_not_rms_per_point():
    """k3 = 0.05 left out: sigma per coordinate 1.2x the noise (below fit_ratio_doubtful), RMS per point 1.7x."""
    rng = np.random.default_rng(2)
    obj, img = _views(16, rng, [-0.25, 0.04, 0.0, 0.0, 0.05])
    res = calibrate(obj, img, dt.IMAGE_SIZE)
    q = res.quality()
    sigma = _sigma_per_coordinate(res)
    assert sigma / q.noise_sigma < limits.LIMITS["fit_ratio_doubtful"].value < res.rms / q.noise_sigma
    assert not any(f.code == "fit" for f in q.findings), q.warnings()
    assert q.richer is None  # nothing fitted below the limit


def test_image_corners_never_seen_are_advice_not_bad(real):
    """Six views of OpenCV's left set (1, 3, 6, 7, 8, 9) leave the image corners uncertain by many pixels (over
    the old 4 px "bad" row, set on 13-view sets only), but the robot's view (the lower half of the image) to a
    few tenths of a pixel: "hold the board there", doubtful, never bad (issue 31: the corners are not where a
    Duckiebot looks at the road). The right set's views reach its corners: no such advice."""
    from dtscal_lib.uncertainty import robot_view_sigma

    side, res = real
    sel = [1, 3, 6, 7, 8, 9] if side == "left" else list(range(res.n_views))
    q = res.refit([res.object_points[i] for i in sel], [res.image_points[i] for i in sel]).quality()
    assert robot_view_sigma(q.uncertainty, res.image_size) < limits.LIMITS["robot_view_sigma_doubtful"].value
    assert q.verdict != "bad", q.warnings()
    corners = [f for f in q.findings if f.code == "uncertainty"]
    if side == "left":
        assert q.uncertainty.corner_mean > 4.0
        assert corners[0].severity == "doubtful" and "hold the board" in corners[0].advice
    else:
        assert corners == [] and q.uncertainty.corner_mean < limits.LIMITS["corner_sigma_doubtful"].value


def test_a_robot_view_the_data_do_not_pin_down_makes_the_verdict_bad():
    """Six small, noisy boards far away in the top of the image only: the lower half of the image, where a
    Duckiebot sees the road, is extrapolated by pixels (above robot_view_sigma_bad): bad, with the advice to
    fill the lower half."""
    from dtscal_lib.uncertainty import robot_view_sigma

    rng = np.random.default_rng(1)
    img = []
    while len(img) < 6:
        r = [*rng.uniform(-0.5, 0.5, 2), rng.uniform(-0.3, 0.3)]
        t = [rng.uniform(-0.3, 0.2), rng.uniform(-0.35, -0.2), rng.uniform(0.6, 0.7)]
        p = camera.project_points(OBJ, r, t, dt.default_K(), dt.default_dist())
        if p.min() > 5 and p[:, 0].max() < 635 and p[:, 1].max() < 200:
            img.append(p + rng.normal(0.0, 0.2, p.shape))
    q = calibrate([OBJ] * 6, img, dt.IMAGE_SIZE).quality()
    f = next(f for f in q.findings if f.code == "robot_view")
    assert robot_view_sigma(q.uncertainty, dt.IMAGE_SIZE) > limits.LIMITS["robot_view_sigma_bad"].value
    assert f.severity == "bad" and q.verdict == "bad" and "lower half" in f.advice
    assert not any(g.code == "uncertainty" for g in q.findings)  # the corners' advice is not repeated


def test_live_tool_and_command_line_give_the_same_verdict_for_the_same_samples(real):
    """The live CALIBRATE solves and judges in its helper process (dtscal_lib.ui.solver); the command line in
    the session itself. The same samples give the same calibration, verdict and image-corner figure."""
    from dtscal_lib.ui.solver import SolverProcess

    side, res = real
    obj, img = list(res.object_points), list(res.image_points)
    skew = side == "right"  # the live solver is told the skew choice too
    cli_result, cli_dropped = calibrate_without_outlier_views(obj, img, res.image_size, model=res.model, skew=skew)
    cli = assess_quality(cli_result)
    solver = SolverProcess()
    try:
        assert solver.ready(wait=60)
        live_result, live_dropped = solver.calibrate(obj, img, res.image_size, res.model, skew=skew)
        live = solver.assess(live_result)
    finally:
        solver.close()
    assert list(live_dropped) == list(cli_dropped)
    np.testing.assert_allclose(live_result.K, cli_result.K, rtol=1e-9)
    assert live_result.skew == cli_result.skew == skew
    assert live.verdict == cli.verdict and [f.code for f in live.findings] == [f.code for f in cli.findings]
    assert live.uncertainty.corner_mean == pytest.approx(cli.uncertainty.corner_mean, rel=1e-9)


@pytest.mark.parametrize("n_views", [4, 5])
def test_sigma_covers_as_often_as_it_says_at_few_views(real, n_views):
    """30 random subsets of n views: +-1 sigma of fx, fy, cx, cy covers the 13-view value 55-85 % of the time
    (issue 21's acceptance; an honest sigma covers 68 %). The subsets are drawn here, calibrated with the
    kit's calibrate, and judged against the full set's values."""
    side, res = real
    ref = np.array([res.K[0, 0], res.K[1, 1], res.K[0, 2], res.K[1, 2]])
    rng = np.random.default_rng(0)
    hits = []
    for _ in range(30):
        pick = sorted(rng.choice(res.n_views, n_views, replace=False))
        r = calibrate([res.object_points[i] for i in pick], [res.image_points[i] for i in pick], res.image_size)
        v = np.array([r.K[0, 0], r.K[1, 1], r.K[0, 2], r.K[1, 2]])
        hits.append(np.abs(v - ref) <= np.array([r.std[k] for k in ("fx", "fy", "cx", "cy")]))
    covered = float(np.mean(hits))
    assert 0.55 <= covered <= 0.85, (side, n_views, covered)
