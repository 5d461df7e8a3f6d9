"""The suite does not depend on where the checkout lies: a self-test from a copy under a 0700 folder.

A newcomer who clones as root into their home folder, or CI cloning into a ``mktemp -d`` folder,
has a checkout that other users cannot enter; the tests that drop to ``nobody`` (permission tests
that must be real under root) once read their inputs from the checkout and failed there. This test
copies the checkout (without .git, .venv and caches) into a fresh ``mkdtemp`` folder (mode 0700),
and runs a representative, quick part of the suite from the copy with the same interpreter: the
file-writing and option-checking tests, including every test that runs as ``nobody``. The copy's own
``dtscal_lib`` is the one imported (checked). Slow: about 30-60 s.
"""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parent.parent
#: the part of the suite run from the copy: every test that runs as nobody, and the file writers around them
REPRESENTATIVE = ["tests/test_calib_files.py", "tests/test_validation.py"]
SKIP = shutil.ignore_patterns(".git", ".venv", "__pycache__", ".pytest_cache", ".hypothesis", ".ruff_cache",
                              "*.egg-info", ".ipynb_checkpoints", "workspace")


def test_quick_suite_passes_from_a_copy_under_a_0700_folder():
    base = Path(tempfile.mkdtemp(prefix="dtscal-0700-"))
    try:
        assert stat.S_IMODE(base.stat().st_mode) == 0o700
        copy = base / "checkout"
        shutil.copytree(ROOT, copy, ignore=SKIP, symlinks=True)
        env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")
        env.pop("PYTEST_XDIST_WORKER", None)
        where = subprocess.run([sys.executable, "-c", "import dtscal_lib; print(dtscal_lib.__file__)"], cwd=copy,
                               env=env, capture_output=True, text=True, timeout=600)
        assert Path(where.stdout.strip()).is_relative_to(copy), where.stdout + where.stderr
        run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:xdist",
                              "-m", "not slow", *REPRESENTATIVE], cwd=copy, env=env, capture_output=True, text=True,
                             timeout=540)  # a safety net (pytest-timeout: 600 s); it takes about a minute
        assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-2000:]
        assert " passed" in run.stdout, run.stdout[-2000:]
    finally:
        shutil.rmtree(base, ignore_errors=True)
