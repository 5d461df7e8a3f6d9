"""nbval as an autograder: with DTSCAL_STRICT=1, `pytest --nbval-lax` fails exactly for notebooks whose
self-checks do not all pass; without it (as in JupyterLab) the same notebook runs to the end."""

from __future__ import annotations

import os
import subprocess
import sys

import nbformat
import pytest

from dtscal_lib.teaching.release import inject_solutions
from nbtools import NOTEBOOKS, ROOT, SOLUTIONS

NB = "01_pinhole_projection.ipynb"


def _nbval(path, strict: bool) -> subprocess.CompletedProcess:
    env = dict(os.environ, DTSCAL_STRICT="1" if strict else "")
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--nbval-lax", str(path)],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)


@pytest.mark.slow
@pytest.mark.parametrize("solved, strict, ok", [(False, True, False), (True, True, True), (False, False, True)])
def test_nbval_strict(tmp_path, solved, strict, ok):
    nb = nbformat.read(NOTEBOOKS / NB, as_version=4)
    if solved:
        nb = inject_solutions(nb, nbformat.read(SOLUTIONS / NB, as_version=4))
    path = tmp_path / NB
    nbformat.write(nb, path)
    run = _nbval(path, strict)
    assert (run.returncode == 0) == ok, run.stdout[-3000:]
    if not ok:
        assert "SelfCheckFailed" in run.stdout and "not implemented" in run.stdout
