"""``dtscal handin``: one zip of the student's workspace notebooks, for the instructor or Gradescope.

The zip holds the notebooks of ``workspace/`` (the seven course notebooks the student writes in,
under their course names, at the top of the zip) and nothing else: no backups, nothing of the
kit. It is named for the student (``handin/<name>.zip``), so that ``dtscal grade handin/ada.zip``
grades it as the student ``ada``, and Gradescope, which unpacks an uploaded zip into the
submission folder, finds the notebooks where it looks for them.
"""

from __future__ import annotations

import getpass
import re
import subprocess
import zipfile
from pathlib import Path

from .. import safe_write
from ..errors import DtscalError

HANDIN = "handin"


def student_name(name: str | None = None) -> str:
    """A file-name-safe student name: ``name``, else git's ``user.name``, else the login name."""
    raw = (name or "").strip()
    if not raw:
        try:
            raw = subprocess.run(["git", "config", "user.name"], capture_output=True, text=True, timeout=10,
                                 check=False).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            raw = ""
    if not raw:
        try:
            raw = getpass.getuser()
        except (KeyError, OSError):
            raw = ""
    safe = re.sub(r"[^A-Za-z0-9_-]+", "_", raw).strip("_")
    if not safe:
        raise DtscalError("cannot tell your name for the hand-in file; give it: dtscal handin --name YOUR_NAME")
    return safe[:64]


def workspace_notebooks(root) -> list[Path]:
    ws = Path(root) / "workspace"
    nbs = sorted(p for p in ws.glob("*.ipynb") if not p.name.startswith(".")) if ws.is_dir() else []
    if not nbs:
        raise DtscalError(f"no notebook in {ws}: open the course once (bash start.sh) and write your code there, "
                          "then hand in")
    return nbs


def write_handin(root, name: str | None = None, out=None) -> tuple[Path, list[str]]:
    """Write the hand-in zip; returns its path and the notebook names in it.

    Raises
    ------
    DtscalError
        When there is no workspace, a notebook is not valid JSON (the student should fix or
        restore it from ``workspace/backups/``), or the zip cannot be written.
    """
    import json

    root = Path(root)
    nbs = workspace_notebooks(root)
    for p in nbs:
        try:
            json.loads(p.read_text(encoding="utf-8"))
        except (ValueError, OSError) as exc:
            raise DtscalError(f"{p} is not a readable notebook ({type(exc).__name__}); open it in JupyterLab and "
                              "save it again, or copy it back from workspace/backups/") from None
    who = student_name(name)
    target = Path(out) if out else root / HANDIN / f"{who}.zip"
    if target.suffix != ".zip":
        raise DtscalError(f"{target} should end in .zip")
    try:
        with safe_write.output(target, what="hand-in zip", suffix=".part") as tmp, \
                zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
            for p in nbs:
                z.write(p, p.name)
    except OSError as exc:
        raise DtscalError(f"writing {target} failed ({exc.strerror or exc}); free some space or pass "
                          "--out ANOTHER.zip") from None
    return target, [p.name for p in nbs]
