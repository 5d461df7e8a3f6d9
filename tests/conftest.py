"""How the suite runs in parallel, and the fixtures shared by several test files.

``scripts/test.sh`` runs pytest once, ``-n 2 --dist loadfile``: two pytest-xdist workers, a file (a test
module, a solution notebook under nbval, a module's doctests) stays on one worker, so module fixtures are
built once and a notebook's cells run in order in one kernel. No test measures time, so no test needs
the machine to itself (the browser test once did, for its latency; that figure is now
``benchmarks/bench_browser.py``). A plain ``pytest`` runs everything in one process.

Shared fixtures and helpers live here or in helper modules next to the tests (``ros_env.py``,
``live_fakes.py``, ``nbtools.py``, ``unprivileged.py``, ...; their fixtures are registered below), never in
another test file: a test file is a specification and no other file imports it.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from live_fakes import file_server  # noqa: F401 - fixture: a robot's file server on loopback
from ros_env import ros_ok, roscore  # noqa: F401 - fixtures: ROS 1 present (fails under CI), a private roscore

#: the longest files (measured with --durations, longest first), started first by the parallel part so that
#: the two workers end together; every other file keeps its collection order after them
LONGEST_FIRST = (
    "test_notebooks.py", "test_ros_live.py", "test_pipeline.py", "test_synth_regenerate.py", "test_plausibility.py",
    "test_synth.py", "test_handout.py", "test_checkout_anywhere.py", "test_browser_live.py", "test_hub.py",
    "test_nbgrader_export.py",
    "test_outputs_portable.py", "test_report.py", "test_quality.py",
    "test_live_sources.py", "test_grading_sandbox.py", "test_notebook_text.py", "test_ui_calibrator.py",
    "test_charuco.py",
    "test_ui_ros.py", "test_detect_real.py", "test_hostile_input.py", "test_grading_handout.py",
    "test_grading_nbval.py", "test_ros_bag_play.py", "test_course_command.py",
)


@pytest.fixture(scope="session")
def notebook_runs(tmp_path_factory) -> Path:
    """A folder for notebook runs that several tests check (``nbtools.execute_student_once``), one per pytest run,
    shared by its xdist workers (their temporary folders are siblings)."""
    base = tmp_path_factory.getbasetemp()
    return (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "notebook-runs"


def pytest_collection_modifyitems(config, items):
    if os.environ.get("PYTEST_XDIST_WORKER"):  # the workers collect; they all sort alike
        rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
        items.sort(key=lambda it: rank.get(Path(str(it.fspath)).name, len(rank)))  # stable: files stay whole
