"""``dtscal handin``: one zip of the student's workspace notebooks, for the instructor or Gradescope.

The zip holds the notebooks of ``workspace/`` (the seven course notebooks the student writes in,
under their course names, at the top of the zip) and nothing else: no backups, nothing of the
kit. It is named for the student (``handin/<name>.zip``, the name asked once and remembered), so that
``dtscal grade handin/ada.zip`` grades it as the student ``ada``, and Gradescope, which unpacks an uploaded zip into the
submission folder, finds the notebooks where it looks for them.
"""

from __future__ import annotations

import re
import zipfile
from pathlib import Path

from .. import safe_write
from ..errors import DtscalError

HANDIN = "handin"
#: where the student's name for the hand-in file is remembered (inside ``handin/``, which git leaves out)
NAME_FILE = ".name"
#: the git hand-in, as every text of the kit shows it (README, the hand-out's README, docs/ta.md, the
#: ``--handin`` message; tests/test_course_texts.py checks they agree): the workspace only, which is what
#: ``dtscal grade --roster`` grades; ``origin HEAD`` so that the first push needs no upstream set
GIT_HANDIN = 'git add workspace && git commit -m "hand in" && git push origin HEAD'


def _safe(raw: str) -> str:
    return re.sub(r"[^A-Za-z0-9_-]+", "_", raw.strip()).strip("_")[:64]


def student_name(root, name: str | None = None, *, ask=None) -> str:
    """The file-name-safe name of the hand-in: ``name`` (then remembered), else the remembered one, else asked.

    The name is the student's own, asked once and kept in ``handin/.name``: never git's global ``user.name`` or
    the login, which on a shared lab machine name the account, not the student. ``ask`` is called (with the
    question) when no name is known; without it (no terminal) the student is told to pass ``--name``.
    """
    remembered = Path(root) / HANDIN / NAME_FILE
    safe = _safe(name or "")
    if (name or "").strip() and not safe:
        raise DtscalError(f"{name!r} has no letter or digit to name the hand-in file with; give your name: "
                          '--name "Ada Lovelace"')
    if not safe:
        try:
            safe = _safe(remembered.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError):
            safe = ""
    if not safe and ask is not None:
        safe = _safe(ask("Your name, for the hand-in file (asked once; --name changes it): ") or "")
    if not safe:
        raise DtscalError('cannot tell your name for the hand-in file; give it once: bash start.sh --handin --name '
                          '"Ada Lovelace" (in a checkout: dtscal handin --name "Ada Lovelace")')
    try:
        remembered.parent.mkdir(parents=True, exist_ok=True)
        remembered.write_text(safe + "\n", encoding="utf-8")
    except OSError:
        pass  # not remembered: asked again next time, the hand-in itself still works
    return safe


def workspace_notebooks(root) -> list[Path]:
    ws = Path(root) / "workspace"
    nbs = sorted(p for p in ws.glob("*.ipynb") if not p.name.startswith(".")) if ws.is_dir() else []
    if not nbs:
        raise DtscalError(f"no notebook in {ws}: open the course once (bash start.sh) and write your code there, "
                          "then hand in")
    return nbs


def write_handin(root, name: str | None = None, out=None, *, ask=None) -> tuple[Path, list[str]]:
    """Write the hand-in zip; returns its path and the notebook names in it.

    ``handin/`` holds one zip: a hand-in under another name (``--name`` changed) replaces the earlier zip,
    so the student cannot upload a stale one. ``ask`` asks the student's name when none is known
    (:func:`student_name`).

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
    who = student_name(root, name, ask=ask)
    target = Path(out) if out else root / HANDIN / f"{who}.zip"
    if target.suffix != ".zip":
        raise DtscalError(f"{target} should end in .zip")
    try:
        with safe_write.output(target, what="hand-in zip", suffix=".part") as tmp, \
                zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
            for p in nbs:
                z.write(p, p.name)
        if out is None:  # one zip in handin/: the earlier ones (another name) go
            for old in target.parent.glob("*.zip"):
                if old != target:
                    old.unlink()
    except OSError as exc:
        raise DtscalError(f"writing {target} failed ({exc.strerror or exc}); free some space or pass "
                          "--out ANOTHER.zip") from None
    return target, [p.name for p in nbs]
