"""Checks at the grader's start: what would make every student "grader error" is refused before grading.

Debian's ``python3-numpy`` reaches BLAS through the alternatives system: its ``_multiarray_umath`` needs
``libblas.so.3``, and ``/usr/lib/<arch>/libblas.so.3`` is a symlink to ``/etc/alternatives/libblas.so.3-<arch>``
(Debian's BLAS packages register ``libblas.so.3`` with ``update-alternatives(1)``; the link on a Debian 12
machine: ``/etc/alternatives/libblas.so.3-x86_64-linux-gnu -> .../openblas-pthread/libblas.so.3``). A
sandbox that shows ``/usr`` but not ``/etc`` leaves that link dangling: numpy fails to import inside it and
every check of every student would be a grader error. So before grading, the interpreter and numpy a
submission gets are tried once, inside the sandbox, on a matrix product (BLAS); a failure is a refusal at
start that names the library and the fix, never a class of "grader error" rows.
"""

from __future__ import annotations

import subprocess
import threading

from ..errors import DtscalError

#: numpy imported and one BLAS call made (a 2x2 product): what every check needs
PROBE = "import numpy; a = numpy.ones((2, 2)); print(float((a @ a)[0, 0]))"
PROBE_OUT = "2.0"

_LOCK = threading.Lock()
_DONE: dict = {}


def _reason(stderr: str) -> str:
    """numpy's own "Original error was: ..." line, else the last line of the error."""
    lines = [ln.strip() for ln in stderr.splitlines() if ln.strip()]
    for ln in reversed(lines):
        if ln.startswith("Original error was:"):
            return ln.removeprefix("Original error was:").strip()
    return lines[-1] if lines else "no output"


def check_numpy() -> None:
    """Refuse (:class:`DtscalError`) when numpy cannot load and multiply inside the sandbox; once per
    interpreter, numpy and sandbox mode in this process."""
    from . import sandbox

    key = (sandbox.INTERPRETER, sandbox.NUMPY_SITE, sandbox.mode())
    with _LOCK:
        if key in _DONE:
            return
    argv = sandbox.probe_argv(PROBE)
    try:
        run = subprocess.run(argv, capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
        ok, why = run.returncode == 0 and run.stdout.strip() == PROBE_OUT, _reason(run.stderr)
    except (OSError, subprocess.SubprocessError) as exc:
        ok, why = False, str(exc)
    if not ok:
        exe, _binds, numpy_binds = sandbox._python()
        where = numpy_binds[0] if numpy_binds else "numpy"
        debian = "/dist-packages/" in where
        hint = ("This is Debian's python3-numpy, which finds BLAS through /etc/alternatives (libblas.so.3 -> "
                "/etc/alternatives/libblas.so.3-<arch>), outside what the sandbox shows. " if debian else "")
        raise DtscalError(
            f"not graded: numpy ({where}, run by {exe}) cannot load inside the grading sandbox "
            f"({sandbox.mode()}): {why}. {hint}Every student would get 'grader error', so nothing was graded. "
            "Grade from the kit's own environment, whose numpy (from PyPI) carries its own OpenBLAS: "
            "bash scripts/setup.sh, then .venv/bin/dtscal grade ...")
    with _LOCK:
        _DONE[key] = True
