"""An interpreter and a numpy that an ordinary user can read, for the sandbox's tests as that user.

The test venv's Python may lie where ``nobody`` cannot read it (pyenv under ``/root``, a checkout
in a 0700 folder). :func:`readable_python` gives one that it can: Debian's ``/usr/bin/python3.X``
of the same minor version when it exists (world-readable), else a copy of the base
interpreter's prefix; and a copy of this venv's ``numpy`` (+ ``numpy.libs``) in ``folder``
(0755). :func:`use` points the sandbox at them (inside the unprivileged child only).
"""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

import numpy


def _readable_tree(root: Path) -> None:
    for d, dirs, files in os.walk(root):
        os.chmod(d, 0o755)
        for f in files:
            p = os.path.join(d, f)
            if not os.path.islink(p):
                os.chmod(p, 0o755 if os.access(p, os.X_OK) else 0o644)


def readable_python(folder: Path) -> tuple[str, str]:
    """(interpreter, folder holding numpy), both readable by every user."""
    folder = Path(folder)
    site = folder / "site"
    if not (site / "numpy").is_dir():
        src = Path(numpy.__file__).resolve().parent
        shutil.copytree(src, site / "numpy", symlinks=True)
        if (src.parent / "numpy.libs").is_dir():
            shutil.copytree(src.parent / "numpy.libs", site / "numpy.libs", symlinks=True)
        _readable_tree(site)
    minor = f"python{sys.version_info.major}.{sys.version_info.minor}"
    system = Path("/usr/bin") / minor
    if system.is_file():
        return str(system), str(site)
    prefix = folder / "python"
    if not prefix.is_dir():
        shutil.copytree(sys.base_prefix, prefix, symlinks=True,
                        ignore=shutil.ignore_patterns("site-packages", "__pycache__", "test", "tests"))
        _readable_tree(prefix)
    return str(prefix / "bin" / minor), str(site)


def use(interpreter: str, site: str) -> None:
    """Point the sandbox at ``interpreter`` and ``site`` (call it in the unprivileged child)."""
    from dtscal_lib.grading import sandbox

    sandbox.INTERPRETER, sandbox.NUMPY_SITE = interpreter, site
    sandbox._PROBE.clear()
