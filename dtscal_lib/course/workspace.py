"""The student's workspace: a copy of the generated notebooks that students write in, kept across updates.

``notebooks/`` is generated from ``solutions/`` and never edited (``dtscal release --check``
guards it). ``dtscal course`` serves ``workspace/`` instead, created from ``notebooks/`` on
first run. Each exercise's stub sits between ``### BEGIN YOUR CODE`` and ``### END YOUR CODE``;
when the instructor ships corrected notebooks, ``dtscal course --update`` builds each
workspace notebook afresh from ``notebooks/`` and carries the student's code regions into it
(matched by function name), keeps the old notebook as a backup, and reports what could not
be carried over.
"""

from __future__ import annotations

import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import nbformat

from ..errors import DtscalError
from ..release import BEGIN_YOURS, END_YOURS

__all__ = ["WORKSPACE", "BEGIN_YOURS", "END_YOURS", "ensure_workspace", "update_workspace", "UpdateReport",
           "student_regions"]

WORKSPACE = "workspace"
BACKUPS = "backups"


def _notebooks(src: Path) -> list[Path]:
    if not src.is_dir():
        raise DtscalError(f"no notebooks folder at {src}; run `dtscal release --write` in the kit checkout")
    paths = sorted(p for p in src.glob("*.ipynb") if not p.name.startswith("."))
    if not paths:
        raise DtscalError(f"{src} holds no notebook; run `dtscal release --write` in the kit checkout")
    return paths


def ensure_workspace(root) -> Path:
    """``root/workspace`` with every notebook of ``root/notebooks`` (missing ones copied; none overwritten)."""
    root = Path(root)
    ws = root / WORKSPACE
    ws.mkdir(exist_ok=True)
    for nb in _notebooks(root / "notebooks"):
        if not (ws / nb.name).exists():
            shutil.copyfile(nb, ws / nb.name)
    return ws


def _regions(source: str, where: str) -> dict[str, tuple[int, int]]:
    """``### BEGIN YOUR CODE`` .. ``END`` regions of a cell: function name -> (begin line, end line)."""
    from ..release import find_regions

    return {func: (b, e) for b, e, func in find_regions(source, where, begin=BEGIN_YOURS, end=END_YOURS)}


def student_regions(nb) -> tuple[dict[str, list[str]], list[str]]:
    """The code between the YOUR CODE markers of every exercise cell, keyed by function name.

    Returns the regions and a list of problems (an exercise cell whose markers are missing or broken).
    """
    out, problems = {}, []
    for i, cell in enumerate(nb.cells):
        if cell.cell_type != "code" or "exercise" not in cell.get("metadata", {}).get("tags", []):
            continue
        lines = cell.source.split("\n")
        try:
            regions = _regions(cell.source, f"cell {i}")
        except DtscalError as exc:
            problems.append(str(exc))
            continue
        if not regions:
            problems.append(f"cell {i}: the '{BEGIN_YOURS}' / '{END_YOURS}' markers were removed")
        for func, (b, e) in regions.items():
            out[func] = lines[b + 1:e]
    return out, problems


@dataclass
class UpdateReport:
    """What :func:`update_workspace` did, per notebook."""

    carried: dict = field(default_factory=dict)     # notebook -> [function]
    not_carried: list = field(default_factory=list)  # human-readable lines
    added: list = field(default_factory=list)        # notebooks new in the workspace
    backups: list = field(default_factory=list)      # paths of the old notebooks

    @property
    def ok(self) -> bool:
        return not self.not_carried

    def text(self) -> str:
        lines = []
        for name, funcs in self.carried.items():
            lines.append(f"{name}: carried over your {', '.join(funcs) if funcs else 'notebook (no code written yet)'}")
        for name in self.added:
            lines.append(f"{name}: new in this version of the course, copied into your workspace")
        if self.not_carried:
            lines.append("COULD NOT CARRY OVER (copy it by hand from the backup):")
            lines += [f"  {line}" for line in self.not_carried]
        if self.backups:
            lines.append("your previous notebooks are kept in " + str(Path(self.backups[0]).parent))
        lines.append("only the code between the YOUR CODE markers is carried over; other edits (notes, "
                     "extra cells) are in the backups")
        return "\n".join(lines)


def _stub_lines(lines: list[str]) -> bool:
    body = [line.strip() for line in lines if line.strip()]
    return all(line.startswith("#") or line.startswith("raise NotImplementedError") for line in body)


def update_workspace(root, *, stamp: str | None = None) -> UpdateReport:
    """Rebuild ``root/workspace`` from ``root/notebooks``, keeping the student's code regions.

    For every notebook: the old workspace copy is backed up to
    ``workspace/backups/<stamp>/``; the new notebook is written with the student's code
    (between the YOUR CODE markers, matched by function name) in place of its stubs.
    Functions whose code cannot be placed (markers removed, function gone from the new
    version) are listed in the report; their code stays in the backup.
    """
    root = Path(root)
    ws = root / WORKSPACE
    report = UpdateReport()
    if not ws.is_dir():
        ensure_workspace(root)
        report.added = [p.name for p in _notebooks(root / "notebooks")]
        return report
    stamp = stamp or time.strftime("%Y%m%d-%H%M%S")
    backup_dir = ws / BACKUPS / stamp
    for new_path in _notebooks(root / "notebooks"):
        old_path = ws / new_path.name
        if not old_path.exists():
            shutil.copyfile(new_path, old_path)
            report.added.append(new_path.name)
            continue
        try:
            old = nbformat.read(str(old_path), as_version=4)
        except Exception as exc:
            report.not_carried.append(f"{new_path.name}: your notebook cannot be read ({exc}); left as it is")
            continue
        new = nbformat.read(str(new_path), as_version=4)
        mine, problems = student_regions(old)
        report.not_carried += [f"{new_path.name}: {p}" for p in problems]
        placed = []
        for i, cell in enumerate(new.cells):
            if cell.cell_type != "code" or "exercise" not in cell.get("metadata", {}).get("tags", []):
                continue
            lines = cell.source.split("\n")
            regions = _regions(cell.source, f"{new_path.name}, cell {i}")
            for func, (b, e) in sorted(regions.items(), key=lambda kv: -kv[1][0]):
                if func in mine and not _stub_lines(mine[func]):
                    lines[b + 1:e] = mine[func]
                    placed.append(func)
            cell.source = "\n".join(lines)
        written = [f for f, body in mine.items() if not _stub_lines(body)]
        for func in written:
            if func not in placed:
                report.not_carried.append(f"{new_path.name}: your `{func}` has no place in the new notebook")
        backup_dir.mkdir(parents=True, exist_ok=True)
        shutil.copy2(old_path, backup_dir / old_path.name)
        report.backups.append(str(backup_dir / old_path.name))
        nbformat.write(new, str(old_path))
        report.carried[new_path.name] = sorted(placed)
    return report


FIRST_NOTEBOOK = "01_pinhole_projection.ipynb"


def jupyter_command(root, *, instructor: bool = False, port: int = 8888, ip: str | None = None,
                    no_browser: bool = False) -> list[str]:
    """The JupyterLab command line of ``dtscal course``.

    Students get JupyterLab rooted at ``workspace/`` (created on first run), so no solution
    is reachable from the file browser; the instructor (``instructor=True``) gets it rooted at
    ``solutions/``. Either way it opens notebook 01 (``/lab/tree/<notebook>``; with
    ``no_browser`` the printed address points there).
    """
    import os
    import sys

    root = Path(root)
    if instructor:
        folder = root / "solutions"
        if not folder.is_dir():
            raise DtscalError(f"no solutions/ in {root}: --instructor needs the instructor's kit, not a hand-out")
    else:
        folder = ensure_workspace(root)
    cmd = [sys.executable, "-m", "jupyterlab", f"--ServerApp.root_dir={folder}", f"--port={port}"]
    if (folder / FIRST_NOTEBOOK).exists():
        cmd.append(f"--LabApp.default_url=/lab/tree/{FIRST_NOTEBOOK}")  # also the printed URL
    if no_browser:
        cmd.append("--no-browser")
    if ip:
        cmd.append(f"--ip={ip}")
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        cmd.append("--allow-root")  # containers and course VMs often run as root
    return cmd
