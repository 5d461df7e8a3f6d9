"""Stored notebook outputs do not depend on the machine's floating-point round-off (issue 7, item 4).

nbval compares every stored text output of solutions/. A number whose digits come from
round-off (a noise-free fit's residual, a nearly singular system) differs between BLAS kernels
and thread counts, so a notebook printing one passes here and fails on another machine. This
test re-executes the solution notebooks under a different numeric configuration (OpenBLAS's
oldest generic x86-64 kernel, one thread instead of two, MKL's compatibility path) and compares
them with nbval, so such a difference shows on the developer's machine first.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from nbtools import ROOT

CONFIGS = {
    "generic-kernel-1-thread": {"OPENBLAS_CORETYPE": "Prescott", "OPENBLAS_NUM_THREADS": "1",
                                "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "MKL_CBWR": "COMPATIBLE"},
}


@pytest.mark.slow
@pytest.mark.timeout(1800)
@pytest.mark.parametrize("name", sorted(CONFIGS))
def test_solution_outputs_match_under_another_numeric_configuration(name):
    env = dict(os.environ, **CONFIGS[name])
    cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--nbval", "--nbval-current-env",
           "--nbval-sanitize-with", str(ROOT / "solutions" / "nbval_sanitize.cfg"), str(ROOT / "solutions")]
    run = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=1700)
    assert run.returncode == 0, f"nbval under {CONFIGS[name]}:\n{run.stdout[-6000:]}\n{run.stderr[-2000:]}"
