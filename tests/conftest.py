"""How the suite is split for speed: which tests run alone, and the order the parallel part starts files in.

``scripts/test.sh`` runs pytest twice over the same collection:

1. ``--dtscal-part parallel -n 2 --dist loadfile``: everything not marked ``serial``, on two pytest-xdist
   workers. A file (a test module, a solution notebook under nbval, a module's doctests) stays on one
   worker, so module fixtures are built once and a notebook's cells run in order in one kernel.
2. ``--dtscal-part serial``: the ``serial`` tests, one at a time with nothing else running.

A plain ``pytest`` (no ``--dtscal-part``) runs everything in one process, as before.

``serial`` is given here, by file, rather than in the test files: a test is serial when it measures
time against a budget that another test running beside it would eat (the browser test's
frame-to-page latency).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

#: test files whose tests run alone (the serial part)
SERIAL_FILES = {
    "test_browser_live.py",  # measures the latency from a frame's arrival to its display in the page
}

#: the longest files (measured with --durations, longest first), started first by the parallel part so that
#: the two workers end together; every other file keeps its collection order after them
LONGEST_FIRST = (
    "test_notebooks.py", "test_ros_live.py", "test_pipeline.py", "test_synth_regenerate.py", "test_plausibility.py",
    "test_synth.py", "test_handout.py", "test_outputs_portable.py", "test_report.py", "test_quality.py",
    "test_live_sources.py", "test_grading_sandbox.py", "test_notebook_text.py", "test_ui_calibrator.py",
    "test_ui_ros.py", "test_detect_real.py", "test_hostile_input.py", "test_grading_handout.py",
    "test_grading_nbval.py", "test_ros_bag_play.py", "test_course_command.py",
)

PARTS = ("all", "parallel", "serial")


def pytest_addoption(parser):
    parser.addoption("--dtscal-part", choices=PARTS, default="all",
                     help="run only the tests not marked serial (parallel), only the serial ones (serial), or all "
                          "(the default); scripts/test.sh runs 'parallel' under pytest-xdist, then 'serial'")


@pytest.fixture(scope="session")
def notebook_runs(tmp_path_factory) -> Path:
    """A folder for notebook runs that several tests check (``nbtools.execute_student_once``), one per pytest run,
    shared by its xdist workers (their temporary folders are siblings)."""
    base = tmp_path_factory.getbasetemp()
    return (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "notebook-runs"


def _is_serial(item) -> bool:
    return item.get_closest_marker("serial") is not None


def pytest_collection_modifyitems(config, items):
    for item in items:
        if Path(str(item.fspath)).name in SERIAL_FILES:
            item.add_marker(pytest.mark.serial)
    part = config.getoption("--dtscal-part")
    if part != "all":
        keep = [it for it in items if _is_serial(it) == (part == "serial")]
        drop = [it for it in items if _is_serial(it) != (part == "serial")]
        if drop:
            config.hook.pytest_deselected(items=drop)
            items[:] = keep
    if part == "parallel":
        rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
        items.sort(key=lambda it: rank.get(Path(str(it.fspath)).name, len(rank)))  # stable: files stay whole
