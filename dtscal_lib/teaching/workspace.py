"""The student's workspace: a copy of the generated notebooks that students write in, kept across updates.

``notebooks/`` is generated from ``solutions/`` and never edited (``dtscal release --check``
guards it). ``dtscal course`` serves ``workspace/`` instead, created from ``notebooks/`` on
first run; ``workspace/.course/`` keeps the course version each notebook was last built from
(hidden in JupyterLab), so an update can tell the student's edits from the instructor's.

``dtscal course --update`` (``bash start.sh --update``) merges every workspace notebook with the
new ``notebooks/``, cell by cell:

* course cells are matched to the new course by cell id, else by content; a course cell the
  student did not edit takes the new version; one the instructor did not change keeps the
  student's edit; when both changed, the new version comes first and the student's version is
  kept just below it in a marked raw cell;
* the student's own cells (markdown and code) stay where they were: after the same course cell;
* outputs stay on every code cell whose source is unchanged;
* the code between ``### BEGIN YOUR CODE`` and ``### END YOUR CODE`` is carried into the new
  exercise cell of the same function; code that has no place (a renamed or removed function,
  markers deleted) is kept whole in a marked raw cell where the exercise was, never dropped.

Safety: the old notebooks go to a new ``workspace/backups/<stamp>[-N]/`` (never overwritten);
every merged notebook is written to a temporary file first and then renamed over the old one
(``os.replace``), undone if a later rename fails; a lock file (``workspace/.update.lock``)
makes a second update wait for the first; every failure raises :class:`DtscalError` with one
line saying what to do, and leaves the workspace as it was. A notebook that is a device, a FIFO or a
dangling link is neither read nor replaced (listed as not carried); a symlinked notebook stays a
link, the file it names is updated (:mod:`dtscal_lib.safe_write`).
"""

from __future__ import annotations

import copy
import errno
import os
import re
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import nbformat

from .. import safe_write
from ..errors import DtscalError
from .release import BEGIN_YOURS, END_YOURS

__all__ = ["WORKSPACE", "BEGIN_YOURS", "END_YOURS", "ensure_workspace", "update_workspace", "UpdateReport",
           "student_regions", "KEPT_TAG"]

WORKSPACE = "workspace"
BACKUPS = "backups"
#: hidden folder of the course version each workspace notebook was built from
BASE = ".course"
LOCK = ".update.lock"
#: a second update waits this long for the first (an update of seven notebooks takes about a second)
LOCK_WAIT_S = 120.0
#: tag of the raw cells in which an update keeps code it could not place
KEPT_TAG = "dtscal_kept"
#: ids the kit gives its own cells (``nb01-03``); JupyterLab gives new cells random ids
_COURSE_ID = re.compile(r"^nb\d\d-\d+$")


def _notebooks(src: Path) -> list[Path]:
    if not src.is_dir():
        raise DtscalError(f"no notebooks folder at {src}; run `dtscal release --write` in the kit checkout")
    paths = sorted(p for p in src.glob("*.ipynb") if not p.name.startswith("."))
    if not paths:
        raise DtscalError(f"{src} holds no notebook; run `dtscal release --write` in the kit checkout")
    return paths


def _os_error(exc: OSError, what: str) -> DtscalError:
    if exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
        fix = "the disk is full: free some space and run the update again"
    elif exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        fix = "it is not writable: make the workspace writable again (chmod -R u+w workspace) and run the update again"
    else:
        fix = f"{exc.strerror or exc}: fix that and run the update again"
    return DtscalError(f"{what} failed ({fix}); nothing was changed")


def ensure_workspace(root) -> Path:
    """``root/workspace`` with every notebook of ``root/notebooks`` (missing ones copied; none overwritten)."""
    root = Path(root)
    ws = root / WORKSPACE
    try:
        ws.mkdir(exist_ok=True)
        for nb in _notebooks(root / "notebooks"):
            if not (ws / nb.name).exists():
                shutil.copyfile(nb, ws / nb.name)
                (ws / BASE).mkdir(exist_ok=True)
                shutil.copyfile(nb, ws / BASE / nb.name)
    except OSError as exc:
        raise _os_error(exc, f"making your workspace in {ws}") from None
    return ws


def _regions(source: str, where: str) -> dict[str, tuple[int, int]]:
    """``### BEGIN YOUR CODE`` .. ``END`` regions of a cell: function name -> (begin line, end line)."""
    from .release import find_regions

    return {func: (b, e) for b, e, func in find_regions(source, where, begin=BEGIN_YOURS, end=END_YOURS)}


def _is_exercise(cell) -> bool:
    tags = cell.get("metadata", {}).get("tags", [])
    return cell.cell_type == "code" and ("exercise" in tags or "practice" in tags)  # practice: written, not graded


def student_regions(nb) -> tuple[dict[str, list[str]], list[str]]:
    """The code between the YOUR CODE markers of every exercise cell, keyed by function name.

    Returns the regions and a list of problems (an exercise cell whose markers are missing or broken).
    """
    out, problems = {}, []
    for i, cell in enumerate(nb.cells):
        if not _is_exercise(cell):
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
    kept: list = field(default_factory=list)         # human-readable lines: code kept in a marked cell
    own_cells: dict = field(default_factory=dict)    # notebook -> number of the student's own cells kept
    not_carried: list = field(default_factory=list)  # human-readable lines: notebooks left as they were
    added: list = field(default_factory=list)        # notebooks new in the workspace
    backups: list = field(default_factory=list)      # paths of the old notebooks

    @property
    def ok(self) -> bool:
        """True when nothing needs the student's attention (nothing kept aside, no notebook left as it was)."""
        return not self.not_carried and not self.kept

    def text(self) -> str:
        lines = []
        for name, funcs in self.carried.items():
            what = f"your {', '.join(funcs)}" if funcs else "your notebook (no code written yet)"
            own = self.own_cells.get(name, 0)
            lines.append(f"{name}: carried over {what}" + (f" and {own} cell(s) of your own" if own else ""))
        for name in self.added:
            lines.append(f"{name}: new in this version of the course, copied into your workspace")
        if self.kept:
            lines.append("KEPT IN A MARKED CELL (look for 'KEPT BY THE UPDATE' and move the code where it belongs):")
            lines += [f"  {line}" for line in self.kept]
        if self.not_carried:
            lines.append("LEFT AS IT WAS (fix it, then run the update again):")
            lines += [f"  {line}" for line in self.not_carried]
        if self.backups:
            lines.append("your previous notebooks are kept in " + str(Path(self.backups[0]).parent))
        return "\n".join(lines)


def _stub_lines(lines: list[str]) -> bool:
    body = [line.strip() for line in lines if line.strip()]
    return all(line.startswith("#") or line.startswith("raise NotImplementedError") for line in body)


def _kept_cell(source: str, why: str):
    cell = nbformat.v4.new_raw_cell(f"# KEPT BY THE UPDATE: {why}\n{source}")
    cell.metadata["tags"] = [KEPT_TAG]
    return cell


def _match(old_nb, new_nb) -> dict[int, int]:
    """old cell index -> new cell index, for the course cells found in both (by id, then by content)."""
    new_ids = {c.get("id"): j for j, c in enumerate(new_nb.cells) if c.get("id")}
    out, used = {}, set()
    for i, c in enumerate(old_nb.cells):
        j = new_ids.get(c.get("id"))
        if j is not None and c.cell_type == new_nb.cells[j].cell_type:
            out[i] = j
            used.add(j)
    by_source: dict[tuple, list[int]] = {}
    for j, c in enumerate(new_nb.cells):
        if j not in used:
            by_source.setdefault((c.cell_type, c.source), []).append(j)
    for i, c in enumerate(old_nb.cells):
        if i not in out and by_source.get((c.cell_type, c.source)):
            out[i] = by_source[(c.cell_type, c.source)].pop(0)
    return out


def _stubbed(source: str) -> str:
    """An exercise cell's source with every YOUR CODE region emptied (what the course wrote around it)."""
    lines = source.split("\n")
    try:
        regions = sorted(_regions(source, "cell").values(), key=lambda r: -r[0])
    except DtscalError:
        return source
    for b, e in regions:
        lines[b + 1:e] = []
    return "\n".join(lines)


def merge_notebook(old, new, base=None, name: str = "notebook", moved: dict | None = None):
    """The new course notebook with everything of the student's from ``old`` in it.

    ``base`` is the course version ``old`` was built from (``None`` when unknown: then every
    course cell whose text differs from the new course is treated as possibly edited and kept).
    ``moved`` maps the cell ids of the other new course notebooks to their names: an edited course
    cell the new course moved there (notebook 03 was split into 03 and 03b) is kept, saying where it went.
    Returns ``(merged notebook, carried functions, kept lines, number of own cells)``.
    """
    merged = copy.deepcopy(new)
    base_by_id = {c.get("id"): c for c in (base.cells if base is not None else []) if c.get("id")}
    base_sources = {(c.cell_type, c.source) for c in (base.cells if base is not None else [])}
    match = _match(old, new)
    mine, _problems = student_regions(old)
    placed, kept = [], []

    # 1. exercise cells of the new course: the student's regions, by function
    for j, cell in enumerate(merged.cells):
        if not _is_exercise(cell):
            continue
        lines = cell.source.split("\n")
        regions = _regions(cell.source, f"{name}, cell {j}")
        for func, (b, e) in sorted(regions.items(), key=lambda kv: -kv[1][0]):
            if func in mine and not _stub_lines(mine[func]):
                lines[b + 1:e] = mine[func]
                placed.append(func)
        cell.source = "\n".join(lines)

    def base_of(c):
        if c.get("id") in base_by_id:
            return base_by_id[c.get("id")]
        return None

    def is_course(i, c):
        if i in match:
            return True
        if base is not None:
            return c.get("id") in base_by_id or (c.cell_type, c.source) in base_sources
        return bool(_COURSE_ID.match(str(c.get("id") or ""))) or _is_exercise(c)

    # 2. course cells: outputs of unchanged ones, the student's edits
    after: dict[int, list] = {}  # new index -> cells to put after it (-1: at the top)
    anchor = -1
    own = 0
    for i, c in enumerate(old.cells):
        if i in match:
            j = match[i]
            anchor = j
            target = merged.cells[j]
            b = base_of(c)
            if _is_exercise(c):
                regions_lost = [f for f, body in _regions_safe(c.source).items()
                                if f not in placed and not _stub_lines(body)]
                outside_edited = b is not None and _stubbed(c.source) != _stubbed(b.source)
                if target.source == c.source and c.cell_type == "code":
                    target.outputs, target.execution_count = c.get("outputs", []), c.get("execution_count")
                elif regions_lost or outside_edited or (b is None and _regions_safe(c.source) == {}
                                                          and c.source != target.source):
                    why = (f"your code for {', '.join(f'`{f}`' for f in regions_lost)} has no place in the new "
                           "notebook (the function was renamed or removed)" if regions_lost else
                           "you edited this exercise cell outside the YOUR CODE markers")
                    after.setdefault(j, []).append(_kept_cell(c.source, why))
                    kept.append(f"{name}: {why}")
                continue
            if c.source == target.source:
                if c.cell_type == "code":
                    target.outputs, target.execution_count = c.get("outputs", []), c.get("execution_count")
                if c.get("attachments"):
                    target["attachments"] = c.attachments
                continue
            edited = (b.source != c.source) if b is not None else c.cell_type == "code"
            if not edited:
                continue  # the instructor changed it; the student did not: the new version
            if b is not None and b.source == target.source:  # only the student changed it: theirs
                target.source = c.source
                if c.cell_type == "code":
                    target.outputs, target.execution_count = c.get("outputs", []), c.get("execution_count")
                continue
            why = "your version of the course cell above (the course changed it too)"
            after.setdefault(j, []).append(_kept_cell(c.source, why))
            kept.append(f"{name}: {why}")
        elif is_course(i, c):
            # a course cell the new course dropped: keep it only if the student changed it
            b = base_of(c)
            regions_lost = [f for f, body in _regions_safe(c.source).items()
                            if f not in placed and not _stub_lines(body)] if _is_exercise(c) else []
            edited = (b is not None and b.source != c.source) or (b is None and base is None and c.cell_type == "code")
            if regions_lost or (edited and not _is_exercise(c)):
                went = (moved or {}).get(c.get("id")) if c.get("id") else None
                why = (f"your code for {', '.join(f'`{f}`' for f in regions_lost)} has no place in the new "
                       "notebook (the function was renamed or removed)" if regions_lost else
                       f"a course cell you edited, which the new course moved to {went}: copy your change there"
                       if went else "a course cell you edited, which the new course no longer has")
                after.setdefault(anchor, []).append(_kept_cell(c.source, why))
                kept.append(f"{name}: {why}")
        else:
            own += 1
            after.setdefault(anchor, []).append(copy.deepcopy(c))
    cells = list(after.get(-1, []))
    for j, cell in enumerate(merged.cells):
        cells.append(cell)
        cells.extend(after.get(j, []))
    merged.cells = cells
    # regions whose cell was neither matched nor a course cell (cannot happen with tags) are kept too
    return merged, sorted(placed), kept, own


def _cell_homes(course: list[Path]) -> dict[str, str]:
    """Cell id -> the new course notebook holding it (ids are unique within a notebook; an unreadable
    notebook is skipped here, and reported where it is merged)."""
    homes: dict[str, str] = {}
    for path in course:
        try:
            nb = nbformat.read(str(path), as_version=4)
        except Exception:  # noqa: BLE001
            continue
        for c in nb.cells:
            if c.get("id"):
                homes.setdefault(c.get("id"), path.name)
    return homes


def _regions_safe(source: str) -> dict[str, list[str]]:
    lines = source.split("\n")
    try:
        return {f: lines[b + 1:e] for f, (b, e) in _regions(source, "cell").items()}
    except DtscalError:
        return {}


class _Lock:
    """An exclusive ``flock`` on ``workspace/.update.lock``: a second update waits, then refuses.

    The file exists only while an update runs: the holder deletes it before it lets go, and a waiter
    that wins the lock on a file already deleted (or replaced) opens the file anew, so two updates never
    hold locks on two different files.
    """

    def __init__(self, path: Path, wait_s: float):
        self.path, self.wait_s, self.fd = path, wait_s, None

    def __enter__(self):
        import fcntl

        try:
            self.fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise _os_error(exc, f"creating the update lock {self.path}") from None
        deadline = time.monotonic() + self.wait_s
        while True:
            try:
                fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                if self._still_the_file():
                    return self
                os.close(self.fd)  # the previous holder deleted it while we waited: lock the new one
                try:
                    self.fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
                except OSError as exc:
                    raise _os_error(exc, f"creating the update lock {self.path}") from None
                continue
            except BlockingIOError:
                if time.monotonic() > deadline:
                    os.close(self.fd)
                    raise DtscalError(
                        f"another update of this workspace is still running (it holds {self.path}); wait for it "
                        "to finish, then run the update again; nothing was changed") from None
                time.sleep(0.2)

    def _still_the_file(self) -> bool:
        try:
            st = os.stat(self.path)
        except FileNotFoundError:
            return False
        mine = os.fstat(self.fd)
        return (st.st_dev, st.st_ino) == (mine.st_dev, mine.st_ino)

    def __exit__(self, *exc):
        try:
            os.unlink(self.path)  # while still holding it: no empty lock file is left behind
        except OSError:
            pass  # a read-only workspace: the (empty) file stays; it is in .gitignore
        os.close(self.fd)  # closing releases the lock


def _unique_dir(parent: Path, stamp: str) -> Path:
    if parent.exists() and not parent.is_dir():
        raise DtscalError(f"{parent} is a file, not a folder; rename or delete it, then run the update again; "
                          "nothing was changed")
    try:
        parent.mkdir(parents=True, exist_ok=True)
        for n in range(1, 10_000):
            d = parent / (stamp if n == 1 else f"{stamp}-{n}")
            try:
                d.mkdir()
                return d
            except FileExistsError:
                continue
    except OSError as exc:
        raise _os_error(exc, f"making a backup folder in {parent}") from None
    raise DtscalError(f"{parent} holds 10000 backups named {stamp}; delete old ones and run the update again")


def _check_writable(path: Path) -> None:
    """Refuse a notebook the student (or the system) made read-only or immutable."""
    try:
        with open(path, "r+b"):
            pass
    except OSError as exc:
        raise DtscalError(
            f"{path} is read-only ({exc.strerror}); make it writable (chmod u+w, or chattr -i) and run the "
            "update again; nothing was changed") from None


def _write_temp(path: Path, nb) -> Path:
    tmp = path.with_name(f".{path.name}.update-{os.getpid()}.tmp")
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(nbformat.writes(nb, version=4) + "\n")
        f.flush()
        os.fsync(f.fileno())
    return tmp


def update_workspace(root, *, stamp: str | None = None, lock_wait_s: float = LOCK_WAIT_S) -> UpdateReport:
    """Merge ``root/workspace`` with ``root/notebooks``, keeping everything of the student's.

    See the module docstring for the rules. The old notebooks are copied to a new
    ``workspace/backups/<stamp>/`` first. Raises :class:`DtscalError` (one line, with the
    fix) when the update cannot be done whole; then nothing in the workspace changed.
    """
    root = Path(root)
    ws = root / WORKSPACE
    report = UpdateReport()
    course = _notebooks(root / "notebooks")
    if not ws.is_dir():
        if ws.exists():
            raise DtscalError(f"{ws} is a file, not a folder; rename it, then run the update again")
        ensure_workspace(root)
        report.added = [p.name for p in course]
        return report
    with _Lock(ws / LOCK, lock_wait_s):
        plans = []  # (name, merged notebook or None (new), old path)
        homes = _cell_homes(course)
        for new_path in course:
            old_path = ws / new_path.name
            try:
                new = nbformat.read(str(new_path), as_version=4)
            except Exception as exc:  # noqa: BLE001 (a damaged course is the instructor's to fix)
                raise DtscalError(f"the course notebook {new_path} cannot be read ({type(exc).__name__}); unpack "
                                  "the course again; nothing was changed") from None
            safe_write.check(ws / BASE / new_path.name, what="course copy of the notebook", through=False)
            if not old_path.exists() and not old_path.is_symlink():
                plans.append((new_path.name, new, None))
                continue
            try:  # a device, a FIFO or a dangling link in the student's place: never read, never replaced
                safe_write.check(old_path, what="notebook", through=False)
            except DtscalError as exc:
                report.not_carried.append(f"{new_path.name}: {exc}; left as it is")
                continue
            try:
                old = nbformat.read(str(old_path), as_version=4)
            except Exception as exc:  # noqa: BLE001 (any unreadable notebook is left alone, and said so)
                report.not_carried.append(f"{new_path.name}: your notebook cannot be read "
                                          f"({type(exc).__name__}); left as it is")
                continue
            base = None
            if (ws / BASE / new_path.name).is_file():
                try:
                    base = nbformat.read(str(ws / BASE / new_path.name), as_version=4)
                except Exception:  # noqa: BLE001 (a broken base only makes the merge more careful)
                    base = None
            _check_writable(old_path)
            try:
                moved = {cid: nb_name for cid, nb_name in homes.items() if nb_name != new_path.name}
                merged, placed, kept, own = merge_notebook(old, new, base, new_path.name, moved)
            except Exception as exc:  # noqa: BLE001 (never lose a notebook to a merge it cannot do)
                report.not_carried.append(f"{new_path.name}: could not be merged ({type(exc).__name__}: {exc}); "
                                          "left as it is")
                continue
            _mine, problems = student_regions(old)
            report.kept += kept
            report.kept += [f"{new_path.name}: {p} (the cell is kept as it was)" for p in problems
                            if not any(new_path.name in k for k in kept)]
            report.carried[new_path.name] = placed
            report.own_cells[new_path.name] = own
            plans.append((new_path.name, merged, old_path))
        if not plans:
            return report
        stamp = stamp or time.strftime("%Y%m%d-%H%M%S")
        backup_dir = None
        temps: list[tuple[Path, Path]] = []  # (temporary file, final path)
        try:
            if any(old for _n, _m, old in plans):
                backup_dir = _unique_dir(ws / BACKUPS, stamp)
                for name, _m, old_path in plans:
                    if old_path is not None:
                        shutil.copy2(old_path, backup_dir / name)
                        report.backups.append(str(backup_dir / name))
            (ws / BASE).mkdir(exist_ok=True)
            for name, merged, _old in plans:  # a symlinked notebook stays a link: the file it names is updated
                for final, nb in ((safe_write.real(ws / name), merged),
                                  (safe_write.real(ws / BASE / name),
                                   nbformat.read(str(root / "notebooks" / name), as_version=4))):
                    temps.append((_write_temp(final, nb), final))
        except (OSError, DtscalError) as exc:
            for tmp, _final in temps:
                tmp.unlink(missing_ok=True)
            if backup_dir is not None:
                shutil.rmtree(backup_dir, ignore_errors=True)
            if isinstance(exc, DtscalError):
                raise
            raise _os_error(exc, "writing the updated notebooks") from None
        _commit(temps)
    for name, _m, old in plans:
        if old is None:
            report.added.append(name)
    return report


def _commit(temps: list[tuple[Path, Path]]) -> None:
    """Rename every temporary file over its target; on a failure put the old files back."""
    saved: list[tuple[Path, Path]] = []  # (hard link of the old file, target)
    done: list[Path] = []
    try:
        for tmp, final in temps:
            if final.exists():
                keep = final.with_name(f".{final.name}.old-{os.getpid()}")
                keep.unlink(missing_ok=True)
                os.link(final, keep)
                saved.append((keep, final))
            os.replace(tmp, final)
            done.append(final)
    except OSError as exc:
        for keep, final in saved:
            os.replace(keep, final)
        for final in done:
            if not any(f == final for _k, f in saved):
                final.unlink(missing_ok=True)
        for tmp, _final in temps:
            tmp.unlink(missing_ok=True)
        raise _os_error(exc, "replacing the notebooks") from None
    for keep, _final in saved:
        keep.unlink(missing_ok=True)


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
