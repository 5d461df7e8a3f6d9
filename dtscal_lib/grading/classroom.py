"""Find the submissions under a path and grade them, several at a time.

A path is one submission (a notebook, a .py file or a hand-in zip), one student's folder
(notebooks named after the assignments, as Gradescope hands them over), or a class folder
holding, in any mix, one folder per student (notebooks, or the zip ``dtscal handin`` wrote),
one zip per student (the zip names the student) or one notebook/.py per student
(``alice.ipynb``; the assignment from ``--assignment``). See :func:`roster`.
"""

from __future__ import annotations

import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import DtscalError
from . import lms
from .archive import read_zip
from .grade import GradeResult, grade_file
from .loader import load_submission
from .material import ASSIGNMENTS, Material, assignment_of

SUFFIXES = (".ipynb", ".py")


@dataclass(frozen=True)
class Item:
    student: str
    path: Path
    assignment: str
    note: str = ""
    #: the file as the class folder names it (``ada.zip/01_pinhole_projection.ipynb``)
    shown: str = ""


@dataclass
class Roster:
    """Everyone under a path: what gets graded, every student (also those with nothing to
    grade), why each other file is not graded, and the class's assignments (the columns:
    the same maximum for every student)."""

    items: list[Item] = field(default_factory=list)
    students: list[str] = field(default_factory=list)
    notes: dict[str, list[str]] = field(default_factory=dict)
    assignments: list[str] = field(default_factory=list)
    #: files of a class folder that belong to no student (``README.txt`` beside the students' folders)
    unplaced: list[str] = field(default_factory=list)
    _scratch: tempfile.TemporaryDirectory | None = None

    def note(self, student: str, text: str) -> None:
        self.notes.setdefault(student, []).append(text)

    def scratch_folder(self) -> Path:
        """A fresh private (0700) folder for one zip's members, removed by :meth:`cleanup`."""
        if self._scratch is None:
            self._scratch = tempfile.TemporaryDirectory(prefix="dtscal-handin-")
        return Path(tempfile.mkdtemp(dir=self._scratch.name))

    def cleanup(self) -> None:
        if self._scratch is not None:
            self._scratch.cleanup()
            self._scratch = None


#: course notebooks that exist but hold no graded exercise: (file-name prefix, a word of the name, why)
UNGRADED = (("06", "duckiebot_camera", "notebook 06 (the Duckiebot camera session) is not graded"),
            ("03b", "calibration_quality", "notebook 03b (calibration quality: predictions and experiments, no "
                                           "exercise function) is not graded"))


def _ungraded(name: str) -> str | None:
    stem = Path(name).stem.lower()
    for prefix, word, why in UNGRADED:
        if stem.startswith(prefix) or word in stem:
            return why
    return None


def _files(folder: Path) -> list[Path]:
    return sorted(p for p in folder.rglob("*") if p.is_file()
                  and not any(part.startswith(".") or part == "__pycache__" for part in p.relative_to(folder).parts))


def same_stem(folders: list[Path], files: list[Path]) -> dict[str, str]:
    """Names that a class folder's hand-ins share (``alice/`` and ``alice.py``, or ``alice.ipynb`` and
    ``alice.zip``): ``{stem: "alice/, alice.py"}``. The rule: each such file is its own student, named by
    the file's whole name (``alice.py``); the folder keeps the bare name. Never merged: one student's
    work never silently takes the place of another's."""
    seen: dict[str, list[str]] = {}
    for d in folders:
        seen.setdefault(d.name, []).append(d.name + "/")
    for p in files:
        seen.setdefault(p.stem, []).append(p.name)
    return {stem: ", ".join(names) for stem, names in seen.items() if len(names) > 1}


def match_by_functions(path: Path) -> str | None:
    """The assignment whose exercise functions ``path`` defines (most of them), or None."""
    try:
        sub = load_submission(path)
    except Exception:  # noqa: BLE001 - unreadable: the grader says why when it grades it
        return None
    counts = {a: sum(f in sub.functions for f in fs) for a, fs in ASSIGNMENTS.items()}
    best = max(counts.values())
    hits = [a for a, n in counts.items() if n == best]
    return hits[0] if best and len(hits) == 1 else None


def roster(path, assignment: str | None = None, *, one_student: str | None = None) -> Roster:
    """Every student and every file under ``path``: graded, or listed with the reason it is not.

    ``path`` is a notebook or .py file (one student, named by the file), a hand-in zip (one
    student, named by the zip), one student's folder (notebooks named after the assignments),
    or a class folder holding, in any mix: a folder per student (notebooks, .py files, the zip
    ``dtscal handin`` wrote, or several of these), a zip per student (named by the zip), a
    notebook per student (with ``--assignment``). ``one_student`` grades everything under
    ``path``, zips included, as that one student's (Gradescope's submission folder).
    Zips are read through :func:`.archive.read_zip` (streamed, capped) into the roster's
    private scratch folder; call :meth:`Roster.cleanup` when done.
    """
    path = Path(path)
    forced = None
    if assignment:
        forced = assignment_of(assignment)
        if forced is None:
            raise DtscalError(f"unknown assignment {assignment!r}; use one of {', '.join(ASSIGNMENTS)}")
    if not path.exists():
        raise DtscalError(f"{path} does not exist: give a notebook, a .py file, a hand-in zip or a folder of "
                          "submissions")
    r = Roster()
    taken: dict[tuple[str, str], str] = {}

    def enrol(student: str) -> None:
        if student not in r.students:
            r.students.append(student)

    def add(student: str, p: Path, rel: str) -> None:
        enrol(student)
        if p.suffix == ".zip":
            return add_zip(student, p, rel)
        if p.suffix not in SUFFIXES:
            r.note(student, f"{rel}: not a notebook (.ipynb), .py file or hand-in zip; not graded")
            return
        why = _ungraded(p.name)
        named = assignment_of(p.name)
        if why and not named:
            r.note(student, f"{rel}: not graded: {why}")
            return
        note = ""
        if forced:
            if named and named != forced:
                r.note(student, f"{rel}: not graded: its name says notebook {named}, not {forced} (--assignment)")
                return
            if not named:
                m = match_by_functions(p)
                if m and m != forced:
                    r.note(student, f"{rel}: not graded as {forced}: it defines the functions of {m}")
                    return
            a = forced
        elif named:
            a = named
        else:
            a = match_by_functions(p)
            if a is None:
                r.note(student, f"{rel}: not graded: the name does not say which notebook it is and it defines "
                                "none of the graded exercise functions (pass --assignment)")
                return
            note = f"{rel}: graded as {a}: the name does not say which notebook it is; its functions are {a}'s"
        if (student, a) in taken:
            r.note(student, f"{rel}: not graded: {taken[student, a]} is already graded as {a}")
            return
        taken[student, a] = rel
        if note:
            r.note(student, note)
        r.items.append(Item(student, p, a, note, rel))

    def add_zip(student: str, z: Path, rel: str) -> None:
        enrol(student)
        got = read_zip(z, r.scratch_folder())
        for n in got.notes:
            r.note(student, n)
        if not got.members and not got.notes:
            r.note(student, f"{rel}: the zip holds no notebook (.ipynb) or .py file; nothing graded")
        for m in got.members:
            add(student, m.path, f"{rel}/{m.name}")

    def add_export(entries: list[lms.Entry]) -> None:
        """Each student's entries newest first: an assignment is graded from the latest file that holds it;
        a file that adds nothing newer is listed as an earlier submission, once, not graded."""
        mine: dict[str, list[lms.Entry]] = {}
        for e in entries:
            mine.setdefault(e.student, []).append(e)
        for student, es in sorted(mine.items()):
            enrol(student)
            graded: list[lms.Entry] = []
            for e in lms.newest_first(es):
                files = _files(e.path) if e.path.is_dir() else [e.path]
                n_items, n_notes = len(r.items), len(r.notes.get(student, []))
                for p in sorted(files, key=lambda p: (p.suffix == ".zip", str(p))):  # loose notebooks first
                    add(student, p, p.relative_to(path).as_posix())
                late = f" ({e.lms} marked it LATE)" if e.late else ""
                if len(r.items) > n_items:
                    graded.append(e)
                    if e.late:
                        r.note(student, f"{e.path.name}: LATE: {e.lms} marked this submission late")
                elif graded:  # superseded: one line instead of a note per notebook in it
                    del r.notes[student][n_notes:]
                    r.note(student, f"{e.path.name}: an earlier submission{late}, not graded: the latest, "
                                    f"{graded[0].path.name}, is")
                elif not files:
                    r.note(student, f"{e.path.name}/: no notebook or .py file handed in (nor a hand-in zip)")

    if path.is_file():
        if path.suffix not in (*SUFFIXES, ".zip"):
            raise DtscalError(f"{path} is not a notebook (.ipynb), a Python file (.py) or a hand-in zip (.zip)")
        exporter = lms.export_zip(path) if path.suffix == ".zip" and not one_student else None
        if exporter:  # the whole class in one zip: never one student's row
            raise DtscalError(f"{path} is a {exporter} export (every file in it is named after a student), not one "
                              f"student's hand-in: unpack it (unzip {path} -d submissions) and grade the folder: "
                              "dtscal grade submissions/")
        add(one_student or path.stem, path, path.name)
    elif one_student:
        enrol(one_student)
        files = _files(path)
        if not files:
            r.note(one_student, "no notebook or .py file handed in (nor a hand-in zip)")
        for p in sorted(files, key=lambda p: (p.suffix == ".zip", str(p))):  # loose notebooks first
            add(one_student, p, p.relative_to(path).as_posix())
    else:
        subdirs = sorted(d for d in path.iterdir() if d.is_dir() and not d.name.startswith((".", "__")))
        top = sorted(p for p in path.iterdir() if p.is_file() and not p.name.startswith("."))
        code = [p for p in top if p.suffix in SUFFIXES]
        zips = [p for p in top if p.suffix == ".zip"]
        named = [p for p in code if assignment_of(p.name) or _ungraded(p.name)]
        exported = lms.recognise([*subdirs, *code, *zips])
        if code and not subdirs and not zips and len(named) == len(code) and not forced \
                and len({assignment_of(p.name) for p in code}) == len(code):
            for p in top:  # one student's folder: notebooks named after the assignments
                add(path.name, p, p.name)
        elif exported:  # a Canvas or Moodle export: one row per student of the LMS, the latest graded
            for p in top:
                if p.suffix not in (*SUFFIXES, ".zip"):
                    r.unplaced.append(f"{p.name}: not a notebook, .py file or hand-in zip of the {exported[0].lms} "
                                      "export; not graded")
            add_export(exported)
        else:
            shared = same_stem(subdirs, [p for p in top if p.suffix in (*SUFFIXES, ".zip")])
            for p in top:
                if p.suffix in (*SUFFIXES, ".zip"):  # one file, one student: named by the file
                    who = p.name if p.stem in shared else p.stem
                    add(who, p, p.name)
                    if p.stem in shared:
                        r.note(who, f"{p.name}: graded as its own student {who!r}: {shared[p.stem]} share the name "
                                    f"{p.stem!r} (a folder and a file, or two files, are two hand-ins); merge "
                                    "them by hand if they are one student's")
                else:
                    r.unplaced.append(f"{p.name}: not a notebook, .py file, hand-in zip or student folder; "
                                      "no student to give it to, not graded")
            for d in subdirs:
                files = _files(d)
                enrol(d.name)
                if not files:
                    r.note(d.name, f"{d.name}/: no notebook or .py file handed in (nor a hand-in zip)")
                for p in sorted(files, key=lambda p: (p.suffix == ".zip", str(p))):  # loose notebooks first
                    add(d.name, p, p.relative_to(path).as_posix())
            if not r.students:
                raise DtscalError(f"{path} holds no notebook (.ipynb), .py or hand-in zip (.zip) submission")
    r.assignments = [forced] if forced else sorted({i.assignment for i in r.items})
    for s in r.students:
        for a in r.assignments:
            if (s, a) not in taken:
                r.note(s, f"{a}: not handed in (0 points)")
    return r


_KEEP: list[Roster] = []


def discover(path, assignment: str | None = None) -> tuple[list[Item], list[str]]:
    """The submissions under ``path`` and the notes on everything else (student: note)."""
    r = roster(path, assignment)
    _KEEP.append(r)  # the members of zips live in the roster's scratch folder: keep it until the process ends
    return r.items, [f"{s}: {n}" for s in r.students for n in r.notes.get(s, [])
                     if " graded as " not in n and not n.endswith("not handed in (0 points)")]


def grade_all(items: list[Item], material: Material, *, jobs: int = 1, progress: bool = False,
              **limits) -> list[GradeResult]:
    """Grade every item, ``jobs`` sandboxes at a time; results in the order of ``items``."""
    for a in sorted({i.assignment for i in items}):
        material.checks(a)  # references once, before the workers start

    def one(item: Item) -> GradeResult:
        res = grade_file(item.path, material, item.assignment, student=item.student, **limits)
        if ".zip/" in item.shown:  # a zip's member: named as in the class folder, not by the scratch copy
            res.submission = item.shown
        return res

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
