"""Grade a roster of students' git repositories, each at a given commit or at the deadline.

A git hand-in without GitHub Classroom (retired on 2026-08-28): each student pushes the hand-out's
repository (its ``workspace/`` notebooks) to any git host the course uses, or the instructor holds a folder
of their clones. ``dtscal grade --roster ROSTER --deadline 2026-12-01T23:59`` clones every repository into a
temporary folder on the instructor's machine, checks out the commit to grade and copies its ``workspace/``
notebooks into a class folder, which is graded like any class folder (:mod:`.classroom`). The hidden cases
never leave the instructor's kit; nothing is pushed to the students' repositories.

ROSTER is either

* a CSV file with the columns ``student,repo`` and an optional ``commit`` (a hash, tag or branch: that
  commit is graded and the deadline does not apply to that student); ``repo`` is a URL git can clone
  (``https://...``, ``git@host:...``, ``file:///...``) or a path, relative to the CSV file's folder; or
* a folder of clones, one per student (the folder's name is the student's).

Which commit: the roster's ``commit`` if given; else with ``--deadline`` the last commit on the repository's
default branch (its HEAD) whose committer date is at or before the deadline (as ``git rev-list --until``);
else the HEAD. A student with no commit before the deadline, or whose repository cannot be cloned, keeps a
row with 0 points and the reason.
"""

from __future__ import annotations

import csv
import math
import os
import shutil
import subprocess
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from ..errors import DtscalError

#: a clone that takes longer is given up (a host that does not answer), with the reason in the student's row
CLONE_TIMEOUT_S = 300
SUFFIXES = (".ipynb", ".py")


@dataclass(frozen=True)
class Entry:
    student: str
    repo: str
    commit: str | None = None


@dataclass
class Checkout:
    """What was graded for one student: the commit (or why none) and the notes for the gradebook."""

    student: str
    repo: str
    commit: str | None = None
    date: str = ""
    notes: list[str] | None = None


def parse_deadline(text: str) -> datetime:
    """``2026-12-01T23:59`` (local time of this machine), ``2026-12-01 23:59+01:00`` or ``...Z``."""
    try:
        when = datetime.fromisoformat(text.strip().replace("Z", "+00:00"))
    except ValueError:
        raise DtscalError(f"--deadline {text!r}: give a date and time as 2026-12-01T23:59 (this machine's time "
                          "zone) or 2026-12-01T23:59+01:00") from None
    if when.tzinfo is None:
        when = when.astimezone()  # the machine's local zone, as git reads a date without a zone
    return when


def _safe_student(name: str) -> str:
    name = name.strip()
    if not name or name in (".", "..") or "/" in name or "\\" in name or name.startswith("."):
        raise DtscalError(f"roster: student name {name!r} cannot be a folder name; use letters, digits, - or _")
    return name


def read_roster(path) -> list[Entry]:
    """The roster's entries (a CSV file or a folder of clones), in its order; a clear error if malformed."""
    path = Path(path)
    if not path.exists():
        raise DtscalError(f"--roster {path} does not exist: give a CSV file (student,repo[,commit]) or a folder "
                          "holding one git clone per student")
    entries: list[Entry] = []
    if path.is_dir():
        for d in sorted(p for p in path.iterdir() if p.is_dir() and not p.name.startswith(".")):
            if not (d / ".git").exists() and not (d / "HEAD").is_file():
                raise DtscalError(f"--roster {path}: {d.name}/ is not a git repository (no .git); the folder must "
                                  "hold one clone per student")
            entries.append(Entry(_safe_student(d.name), str(d.resolve())))
        if not entries:
            raise DtscalError(f"--roster {path} holds no git clone (one folder per student)")
        return entries
    with open(path, newline="", encoding="utf-8-sig") as fh:
        rows = list(csv.DictReader(fh))
    if not rows:
        raise DtscalError(f"--roster {path} is empty: give a header line `student,repo[,commit]` and one row "
                          "per student")
    cols = {c.strip().lower() for c in (rows[0].keys() if rows else []) if c}
    if not {"student", "repo"} <= cols:
        raise DtscalError(f"--roster {path}: the header must name the columns student and repo (and optionally "
                          f"commit); it has {', '.join(sorted(cols)) or 'none'}")
    seen = set()
    for n, row in enumerate(rows, start=2):
        row = {(k or "").strip().lower(): (v or "").strip() for k, v in row.items()}
        student, repo = row.get("student", ""), row.get("repo", "")
        if not student and not repo:
            continue
        if not student or not repo:
            raise DtscalError(f"--roster {path}, line {n}: give both a student and a repo")
        student = _safe_student(student)
        if student in seen:
            raise DtscalError(f"--roster {path}, line {n}: student {student} is listed twice")
        seen.add(student)
        if "://" not in repo and not repo.startswith("git@") and not Path(repo).is_absolute():
            repo = str((path.parent / repo).resolve())
        entries.append(Entry(student, repo, row.get("commit") or None))
    return entries


def _git(*args, cwd=None, timeout=60) -> subprocess.CompletedProcess:
    env = dict(os.environ, GIT_TERMINAL_PROMPT="0", GIT_ASKPASS="true", LC_ALL="C")
    # the students' repositories may belong to other users (a folder of clones): read them anyway
    return subprocess.run(["git", "-c", "safe.directory=*", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=timeout)


def _why(proc: subprocess.CompletedProcess) -> str:
    lines = [x for x in (proc.stderr or proc.stdout).strip().splitlines() if x.strip()]
    return lines[-1] if lines else f"git exited with {proc.returncode}"


def pick_commit(clone: Path, *, commit: str | None = None, deadline: datetime | None = None) -> tuple[str, str]:
    """``(hash, committer date)`` to grade in ``clone``; DtscalError with the reason if there is none."""
    if commit:
        p = _git("rev-parse", "--verify", "--quiet", f"{commit}^{{commit}}", cwd=clone)
        if p.returncode:
            raise DtscalError(f"commit {commit} is not in the repository")
        rev = p.stdout.strip()
    elif deadline is not None:
        # git keeps a commit whose date is <= --until (a commit at the deadline, to the second, counts);
        # commit dates are whole seconds, so a fractional deadline is rounded down to its second
        p = _git("rev-list", "-1", f"--until={math.floor(deadline.timestamp())}", "HEAD", cwd=clone)
        rev = p.stdout.strip()
        if p.returncode or not rev:
            raise DtscalError(f"no commit at or before the deadline {deadline.isoformat(timespec='minutes')}")
    else:
        p = _git("rev-parse", "--verify", "HEAD", cwd=clone)
        if p.returncode:
            raise DtscalError("the repository has no commit")
        rev = p.stdout.strip()
    date = _git("show", "-s", "--format=%cI", rev, cwd=clone).stdout.strip()
    return rev, date


def _copy_notebooks(tree: Path, dest: Path) -> list[str]:
    """The hand-out's ``workspace/`` notebooks (not its backups), else the repository's top-level ones."""
    src = tree / "workspace" if (tree / "workspace").is_dir() else tree
    dest.mkdir(parents=True, exist_ok=True)
    names = []
    for p in sorted(src.iterdir()):
        if p.is_file() and p.suffix in SUFFIXES and not p.name.startswith("."):
            shutil.copy2(p, dest / p.name)
            names.append(p.name)
    return names


def checkout_roster(entries: list[Entry], class_dir, *, deadline: datetime | None = None,
                    work=None) -> list[Checkout]:
    """Clone each repository (into ``work``), check out its commit, copy its notebooks to ``class_dir/STUDENT``.

    Never raises on one student's repository: a clone that fails, or no commit to grade, leaves that
    student's folder empty and says why in :attr:`Checkout.notes`.
    """
    class_dir = Path(class_dir)
    class_dir.mkdir(parents=True, exist_ok=True)
    import tempfile

    own = None
    if work is None:
        own = tempfile.TemporaryDirectory(prefix="dtscal-roster-")
        work = own.name
    out = []
    try:
        for e in entries:
            co = Checkout(e.student, e.repo, notes=[])
            out.append(co)
            folder = class_dir / e.student
            folder.mkdir(exist_ok=True)
            clone = Path(work) / e.student
            try:
                p = _git("clone", "--quiet", "--no-checkout", e.repo, str(clone), timeout=CLONE_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                co.notes.append(f"git: {e.repo} did not answer within {CLONE_TIMEOUT_S} s; not graded (0 points)")
                continue
            if p.returncode:
                co.notes.append(f"git: cannot clone {e.repo} ({_why(p)}); not graded (0 points)")
                continue
            try:
                co.commit, co.date = pick_commit(clone, commit=e.commit, deadline=deadline)
            except DtscalError as exc:
                co.notes.append(f"git: {exc}; nothing graded (0 points)")
                continue
            p = _git("checkout", "--quiet", "--force", co.commit, cwd=clone)
            if p.returncode:
                co.notes.append(f"git: cannot check out {co.commit[:10]} ({_why(p)}); not graded (0 points)")
                co.commit = None
                continue
            names = _copy_notebooks(clone, folder)
            how = "the roster's commit" if e.commit else (
                "the last commit at or before the deadline" if deadline is not None else "the newest commit")
            co.notes.append(f"git: graded commit {co.commit[:10]} of {co.date} ({how}), "
                            f"{len(names)} notebook(s) from "
                            + ("workspace/" if (clone / "workspace").is_dir() else "the repository's top folder"))
    finally:
        if own is not None:
            own.cleanup()
    return out


def zone_given(text: str) -> bool:
    """Whether a ``--deadline`` text names its time zone (``Z``, ``+01:00``); without one it is local time."""
    try:
        return datetime.fromisoformat(text.strip().replace("Z", "+00:00")).tzinfo is not None
    except ValueError:
        return False


def deadline_now_note(deadline: datetime, *, local: bool = False) -> str:
    """The deadline as graded, with its zone said: ``local`` for a deadline given without a zone (read
    in this machine's time zone, as git reads a date without one)."""
    where = f"this machine's local time, {deadline.tzname() or deadline.strftime('%z')}; " if local else ""
    return (f"deadline {deadline.isoformat(timespec='minutes')} ({where}"
            f"{deadline.astimezone(timezone.utc):%Y-%m-%d %H:%M} UTC); a commit at the deadline counts")
