"""Find the submissions under a path and grade them, several at a time.

A path is one submission (a notebook or .py file), one student's folder (notebooks named
after the assignments, as Gradescope hands them over), or a class folder: one notebook/.py
per student (``alice.ipynb``; the assignment from ``--assignment``) or one folder per
student holding several notebooks.
"""

from __future__ import annotations

import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from ..errors import DtscalError
from .grade import GradeResult, grade_file
from .material import ASSIGNMENTS, Material, assignment_of

SUFFIXES = (".ipynb", ".py")


@dataclass(frozen=True)
class Item:
    student: str
    path: Path
    assignment: str


def _files(folder: Path) -> list[Path]:
    return sorted(p for p in folder.rglob("*") if p.is_file() and p.suffix in SUFFIXES
                  and not any(part.startswith(".") or part == "__pycache__" for part in p.relative_to(folder).parts))


def _assignment(path: Path, forced: str | None) -> str | None:
    return forced or assignment_of(path.name)


def discover(path, assignment: str | None = None) -> tuple[list[Item], list[str]]:
    """The submissions under ``path`` and the files that were skipped (with why)."""
    path = Path(path)
    forced = None
    if assignment:
        forced = assignment_of(assignment)
        if forced is None:
            raise DtscalError(f"unknown assignment {assignment!r}; use one of {', '.join(ASSIGNMENTS)}")
    if not path.exists():
        raise DtscalError(f"{path} does not exist: give a notebook, a .py file or a folder of submissions")
    items, skipped = [], []

    def add(student, p):
        a = _assignment(p, forced)
        if a is None:
            skipped.append(f"{p}: cannot tell the assignment from the name; pass --assignment")
        else:
            items.append(Item(student, p, a))

    if path.is_file():
        if path.suffix not in SUFFIXES:
            raise DtscalError(f"{path} is not a notebook (.ipynb) or Python file (.py)")
        add(path.stem, path)
        return items, skipped
    subdirs = sorted(d for d in path.iterdir() if d.is_dir() and not d.name.startswith((".", "__")))
    top = sorted(p for p in path.iterdir() if p.is_file() and p.suffix in SUFFIXES)
    named = [p for p in top if assignment_of(p.name)]
    if named and not subdirs and len({assignment_of(p.name) for p in named}) == len(named) and not forced:
        for p in named:  # one student's folder: notebooks named after the assignments
            add(path.name, p)
        for p in top:  # e.g. 06_duckiebot_camera.ipynb of a `dtscal handin` zip: no hidden cases
            if p not in named:
                skipped.append(f"{p}: not an assignment with hidden cases; not graded")
        return items, skipped
    for p in top:
        add(p.stem, p)
    for d in subdirs:
        files = _files(d)
        if not files:
            skipped.append(f"{d}: no notebook or .py file")
        for p in files:
            add(d.name, p)
    if not items and not skipped:
        raise DtscalError(f"{path} holds no notebook (.ipynb) or .py submission")
    return items, skipped


def grade_all(items: list[Item], material: Material, *, jobs: int = 1, progress: bool = False,
              **limits) -> list[GradeResult]:
    """Grade every item, ``jobs`` sandboxes at a time; results in the order of ``items``."""
    for a in sorted({i.assignment for i in items}):
        material.checks(a)  # references once, before the workers start

    def one(item: Item) -> GradeResult:
        return grade_file(item.path, material, item.assignment, student=item.student, **limits)

    bar = None
    if progress and len(items) > 1:
        from tqdm import tqdm

        bar = tqdm(total=len(items), desc="grading", unit="submission", file=sys.stderr, mininterval=0.5)
    results: list[GradeResult] = []
    with ThreadPoolExecutor(max_workers=max(1, int(jobs))) as pool:
        for res in pool.map(one, items):
            results.append(res)
            if bar is not None:
                bar.update(1)
    if bar is not None:
        bar.close()
    return results
