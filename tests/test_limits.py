"""The one table of belief (dtscal_lib.limits): each threshold once, with a reason and a source, documented.

Every judge reads its numbers from the table (the boards' tilt: the refusal and the verdict's 'bad'
are one value), and docs/limits.md shows the table as the code has it.
"""

from __future__ import annotations

from pathlib import Path

from dtscal_lib import calibration, ground, limits, plausibility, quality
from dtscal_lib.findings import Finding

DOC = Path(__file__).resolve().parents[1] / "docs" / "limits.md"


def test_every_limit_has_a_value_reason_and_source_and_appears_once():
    names = [lim.name for lim in limits.TABLE]
    assert len(names) == len(set(names))
    for lim in limits.TABLE:
        assert lim.reason and lim.source and lim.unit and lim.judge, lim.name


def test_one_value_for_the_tilt_of_the_boards():
    assert plausibility.INTRINSIC_LIMITS["min_tilt_spread_deg"] == quality.TILT_BAD_DEG == limits.TILT_BAD_DEG
    assert quality.TILT_DOUBTFUL_DEG == limits.TILT_DOUBTFUL_DEG > limits.TILT_BAD_DEG
    # the limit of the mathematics is a distinct, named quantity, below the belief
    assert calibration.MIN_TILT_SPREAD_DEG == limits.MIN_TILT_SPREAD_DEG < limits.TILT_BAD_DEG


def test_judges_read_the_table():
    assert plausibility.INTRINSIC_LIMITS is limits.INTRINSIC_LIMITS
    assert ground.GROUND_CAMERA_LIMITS is limits.GROUND_CAMERA_LIMITS
    assert quality.Finding is Finding


def test_fleet_cameras_inside_the_ground_limits():
    """The fleet's own cameras (limits' sources) pass: 0.10-0.123 m, 16-25.3 degrees, axis ratio up to 1.22."""
    lo, hi = limits.GROUND_CAMERA_LIMITS["height_m"]
    assert lo < 0.10 and 0.123 < hi < 0.335  # --square 0.1 for the 31 mm board: 0.335 m
    lo, hi = limits.GROUND_CAMERA_LIMITS["pitch_down_deg"]
    assert lo < 16 and 25.3 < hi
    assert limits.GROUND_CAMERA_LIMITS["axis_ratio"] > 1.22


def test_docs_show_the_table_as_the_code_has_it():
    assert limits.table_text() in DOC.read_text(encoding="utf-8"), \
        "docs/limits.md is out of date: paste `python -m dtscal_lib.limits` into it"


def test_the_verdict_reads_its_thresholds_from_the_table():
    """The verdict's thresholds are rows of the one table (issue 15: one judge), not constants of quality.py."""
    for name in ("fit_ratio_doubtful", "fit_ratio_bad", "corner_sigma_doubtful", "robot_view_sigma_doubtful",
                 "robot_view_sigma_bad",
                 "view_outlier_factor", "offset_z", "offset_view_share", "radial_z", "radial_fraction",
                 "neighbour_correlation", "systematic_ratio_bad", "min_good_views"):
        assert getattr(quality, name.upper()) == limits.LIMITS[name].value, name
    assert quality.FIT_RATIO_DOUBTFUL < quality.FIT_RATIO_BAD
    assert quality.ROBOT_VIEW_SIGMA_DOUBTFUL < quality.ROBOT_VIEW_SIGMA_BAD


def test_no_limit_cites_a_kit_test_as_its_source():
    """A kit test is a check, never a source (issue 21): each row's data names Duckietown's or ROS's code and
    documents, real files, real photographs or a paper, and no row's source points into tests/."""
    for lim in limits.TABLE:
        assert "tests/" not in lim.source and "test_" not in lim.source, (lim.name, lim.source)
