"""Solutions -> student notebooks, and the student release of the course.

The exercise notebooks in ``solutions/`` are the one source of the course. Each exercise
function is written there once, inside a region::

    def project_points(K, R, t, X):
        \"\"\"docstring the student keeps\"\"\"
        ### BEGIN SOLUTION
        ...the reference code...
        ### END SOLUTION

:func:`student_notebook` replaces every region with a stub that raises
``NotImplementedError`` (at the marker's indentation), clears outputs and drops volatile
metadata, deterministically: the same solution notebook always gives byte-identical
student notebooks, so ``notebooks/`` can be checked against ``solutions/``
(:func:`check_notebooks`) in CI.

Cell conventions the tools rely on (``cell.metadata.tags``):

* ``imports``  - the first code cell: imports and small setup only;
* ``exercise`` - one exercise function per cell, holding exactly one solution region;
  it may use only ``np``, ``cv2``, ``math`` and other exercise functions of the
  notebook, so :func:`solution_functions` can run the imports cell plus the exercise
  cells without the rest of the notebook;
* ``practice`` - a function (or a few) the student writes for their own analysis, with a self-check in
  the notebook but never graded: solution regions become stubs as in ``exercise`` cells, and the
  grader, :func:`solution_functions` and the nbgrader points leave them out;
* ``solution_only`` - (optional) a cell dropped from the student version entirely.
"""

from __future__ import annotations

import ast
import contextlib
import copy
import io
import os
import re
import shutil
from pathlib import Path
from typing import Callable, Iterable

import nbformat
from nbformat import NotebookNode

from ..errors import DtscalError
from ..notebook_format import (  # noqa: F401 - the notebook format, as release's users know it
    _DEF_RE,
    BEGIN,
    END,
    EXERCISE_TAG,
    IMPORTS_TAG,
    PRACTICE_TAG,
    REGION_TAGS,
    SOLUTION_ONLY_TAG,
    _is_marker,
    _lines,
    _read,
    _solution_paths,
    _tags,
    _validate_cells,
    _where,
    find_regions,
)
from .handin import GIT_HANDIN

#: first line of the stub that replaces a region (inject_solutions looks for it)
STUB_COMMENT = "# YOUR CODE HERE: replace the next line with your code"
#: the student's region in a generated notebook (carried over by ``dtscal course --update``)
BEGIN_YOURS, END_YOURS = "### BEGIN YOUR CODE", "### END YOUR CODE"
#: cell metadata the student version keeps; everything else (execution timings, scroll
#: state, collapsed flags...) is dropped
KEEP_CELL_METADATA = ("tags", "editable", "deletable")
#: folder names never shipped to students (grading material, caches)
EXCLUDED_DIRS = frozenset({"grading", "hidden", "__pycache__", ".ipynb_checkpoints", ".pytest_cache"})
EXCLUDED_SUFFIXES = (".pyc", ".pyo")
RELEASE_MARKER = ".dtscal-release"
#: what a student release holds besides the notebooks
RELEASE_TREES = ("dtscal_lib", "data")
RELEASE_FILES = ("pyproject.toml", "LICENSE")
#: the hand-out's own README and one-command start (written by :func:`release`)
#: kit files the hand-out carries (notebook 06 and the robot's error messages name the first; start.sh sources the
#: second; the TA page loses its kit-only parts, :func:`handout_text`);
#: every script a shipped script sources (install-ros.sh's apt-wait.sh) comes along (:func:`sourced_scripts`)
RELEASE_EXTRA = ("scripts/install-ros.sh", "scripts/install-course.sh", "docs/ta.md")
#: the author of the hand-out's first commit: nobody's name, so the students' commits are theirs alone
HANDOUT_AUTHOR = ("dtscal hand-out", "handout@dtscal.invalid")
#: the hand-out is a git repository the student's git hand-in pushes: the student's workspace
#: (with workspace/.course/, which the next update needs) is in it, backups and the environment are not
HANDOUT_GITIGNORE = """.venv/
*.egg-info/
__pycache__/
.ipynb_checkpoints/
workspace/backups/
workspace/.update.lock
workspace/.*.tmp
handin/
"""
STUDENT_README = """# Camera calibration for Duckietown: the course

Seven JupyterLab notebooks in which you write the pieces of camera calibration yourself and then
calibrate a Duckiebot's camera with them. A recorded Duckiebot camera session is included, so no robot
is needed until the last notebook, and not even there.

| notebook | what you write |
| --- | --- |
| `01_pinhole_projection.ipynb` | the pinhole camera: from a 3-D point to a pixel |
| `02_homography.ipynb` | homographies: a flat board in one 3x3 matrix |
| `03_intrinsic_calibration.ipynb` | intrinsic calibration: Zhang's method by hand |
| `03b_calibration_quality.ipynb` | nothing to write: is the calibration good enough, and how much data it needs |
| `04_distortion_rectification.ipynb` | lens distortion and rectification |
| `05_extrinsic_calibration.ipynb` | extrinsic calibration: from pixels to the ground |
| `06_duckiebot_camera.ipynb` | the Duckiebot camera: live calibration in JupyterLab (a robot, or the recording) |

## Start

On a machine with Python 3.11 or newer:

```bash
bash start.sh
```

The first run makes a Python environment in `.venv/` and installs the course into it (under a minute
with a fast connection; it prints each step, a line every few seconds while a step goes on, and the
installer, uv or else pip, lists each package); then JupyterLab opens at notebook 01. Later runs start in
seconds. Options: `bash start.sh --no-browser` prints the address to open instead; `--port 8890` picks
another port; `--setup-only` installs and stops; `bash start.sh --help` lists them all.

## Where you work

You write in `workspace/`, your own copy of the notebooks (JupyterLab shows only this folder).
`notebooks/` holds the course as handed out; do not edit it. Start at `01_pinhole_projection.ipynb` and
go in order: each notebook checks your functions as you go, and until a function passes its check the
notebook uses the kit's stand-in and says so, so every notebook runs to the end.

Write your code between the `### BEGIN YOUR CODE` and `### END YOUR CODE` lines and keep those lines.
Add your own notes and scratch cells wherever you like: they are yours and stay where you put them.

## Handing in

Your instructor says which of the two:

* **A file** (Gradescope or an upload): run `bash start.sh --handin`. It writes `handin/NAME.zip` with
  your seven workspace notebooks; the first time it asks your name and remembers it (`bash start.sh
  --handin --name "Ada Lovelace"` gives or changes it, and replaces the zip: `handin/` holds one). Upload
  that zip as it is.
* **Git**: this folder is a git repository and your work in `workspace/` is part of it (backups and
  `.venv/` are left out by `.gitignore`). Once: `git remote add origin ADDRESS` (the address your course
  gives you) and, if git does not know you yet, `git config user.name "Your Name"` and `git config user.email
  you@example.org`. Then, each time you hand in:

  ```bash
  {git_handin}
  ```

## A new version of the course

If your instructor hands out a corrected course, unpack it into a new folder, copy your old
`workspace/` folder into it, and run `bash start.sh --update` (it then opens the course; the options above
work with it). Every notebook is updated cell by cell:
the course's corrections arrive, and your code, your own cells and the outputs of unchanged cells stay.
Code that has no place in the new notebooks (a function you renamed, say) is kept in a cell marked
`KEPT BY THE UPDATE`; your previous notebooks are kept in `workspace/backups/`. If the update cannot
finish (a full disk, a read-only notebook), it says what to do and changes nothing.

## With a real Duckiebot

Notebook 06 runs on the recording without a robot. To calibrate a real robot, a Duckiebot on Duckietown's
`ente` release or a DD24-B Duckiedrone, put this computer on the robot's network (`ping ROBOT.local` must
answer) and use `dtps:ROBOT` as the source in notebook 06 (your robot's name, e.g. `dtps:autobot01`). That
is all: the kit reaches the robot's camera over DTPS, Duckietown's own link, as Duckietown's Python SDK does,
with what `bash start.sh` installed, on Linux, macOS or Windows. COMMIT stores the calibration on the robot.

A course that runs ROS 1 instead (older Duckiebots, a DD24 on its legacy ROS 1 stack) needs ROS 1 on this
computer (Debian or Ubuntu):

```bash
sudo bash scripts/install-ros.sh
export ROS_MASTER_URI=http://ROBOT.local:11311      # your robot's name, e.g. autobot01
export ROS_IP=$(hostname -I | awk '{print $1}')     # this computer's address on the robot's network
bash start.sh
```

and `ros:ROBOT` as the source. If the robot does not answer, the status line says why and what to do. For
everything a TA sets up, see `docs/ta.md`.
""".replace("{git_handin}", GIT_HANDIN)
#: what ``bash start.sh --help`` prints, at once (before any install), and every option of it works in the hand-out
START_HELP = """usage: bash start.sh [--no-browser] [--port PORT] [--ip IP] [--update] [--setup-only]
       bash start.sh --handin [--name "Your Name"] [--out FILE.zip]

Open the course in JupyterLab at notebook 01 (the first run installs it into .venv, a minute or so).
  --no-browser         print the address to open instead of opening a browser
  --port PORT          serve on another port (default 8888)
  --ip IP              listen on another address (0.0.0.0 in a container)
  --update             carry your work into a corrected course (workspace/ copied in), then open it
  --setup-only         install (and --update) without opening JupyterLab
  --handin             write handin/NAME.zip, your workspace notebooks, to hand in (the name is asked once;
                       --name "Your Name" changes it and replaces the zip)
  --help               this text
"""
START_SH = f"""#!/usr/bin/env bash
# Start the course: make .venv on the first run, install the course into it, open JupyterLab at notebook 01.
# Options: bash start.sh --help. The install (scripts/install-course.sh, shared with the kit's course command) is
# uv's, else pip's, with a line per step and a line every 5 s while a step goes on.
set -euo pipefail
cd "$(dirname "$0")"
case "${{1:-}}" in
  -h|--help) cat <<'HELP'
{START_HELP}HELP
    exit 0 ;;
esac
WHO=start.sh
source scripts/install-course.sh  # after the cd: wherever start.sh was called from
course_installed || install_course
if [ "${{1:-}}" = "--handin" ]; then
  shift
  exec .venv/bin/dtscal handin "$@"
fi
args=()
for a in "$@"; do
  case "$a" in
    --setup-only) args+=("--no-open") ;;
    --instructor|--no-open) say "unknown option $a; see: bash start.sh --help"; exit 2 ;;
    *) args+=("$a") ;;
  esac
done
exec .venv/bin/dtscal course ${{args[@]+"${{args[@]}}"}}
"""

# --------------------------------------------------------------------------- regions
def _stub(indent: str, func: str) -> list[str]:
    """The student's stub, between the YOUR CODE markers that workspace updates carry over."""
    what = f"{func} is not written yet" if func else "this exercise is not written yet"
    return [f"{indent}{BEGIN_YOURS}", f"{indent}{STUB_COMMENT}", f'{indent}raise NotImplementedError("{what}")',
            f"{indent}{END_YOURS}"]


def _indent_of(line: str) -> str:
    return line[: len(line) - len(line.lstrip())]


def strip_regions(source: str, where: str = "cell") -> str:
    """Replace every solution region of ``source`` with the ``NotImplementedError`` stub."""
    lines = _lines(source)
    out, pos = [], 0
    for b, e, func in find_regions(source, where):
        out.extend(lines[pos:b])
        out.extend(_stub(_indent_of(lines[b]), func))
        pos = e + 1
    out.extend(lines[pos:])
    return "\n".join(out)


def region_code(source: str, where: str = "cell") -> dict[str, list[str]]:
    """The code lines inside each region, keyed by function name (markers excluded)."""
    lines = _lines(source)
    return {func: lines[b + 1 : e] for b, e, func in find_regions(source, where)}


# --------------------------------------------------------------------------- notebooks
def _nb_name(nb: NotebookNode, default: str = "notebook") -> str:
    return str(nb.get("metadata", {}).get("dtscal_path", default))


def student_notebook(solution_nb: NotebookNode, name: str | None = None) -> NotebookNode:
    """The student version of a solution notebook.

    Regions become ``raise NotImplementedError`` stubs, cells tagged ``solution_only``
    are dropped, outputs are cleared, execution counts set to ``None``, cell metadata
    reduced to :data:`KEEP_CELL_METADATA` and notebook metadata to the kernel spec and
    the kernel's language_info. The input is not modified; the result depends only on the input.

    Parameters
    ----------
    solution_nb : NotebookNode
        An nbformat 4 notebook.
    name : str, optional
        Names the notebook in error messages.

    Raises
    ------
    DtscalError
        On unbalanced or misplaced solution markers (naming the notebook and cell).
    """
    name = name or _nb_name(solution_nb)
    nb = copy.deepcopy(solution_nb)
    if nb.get("nbformat") != 4:
        raise DtscalError(f"{name}: expected an nbformat 4 notebook, got version {nb.get('nbformat')}")
    _validate_cells(nb, name)
    cells = []
    for i, cell in enumerate(nb.cells):
        if SOLUTION_ONLY_TAG in _tags(cell):
            continue
        md = {k: cell.metadata[k] for k in KEEP_CELL_METADATA if k in cell.get("metadata", {})}
        cell["metadata"] = nbformat.from_dict(md)
        if cell.cell_type == "code":
            cell.source = strip_regions(cell.source, _where(name, i))
            cell.outputs = []
            cell.execution_count = None
        elif "attachments" in cell and not cell.attachments:
            del cell["attachments"]
        cells.append(cell)
    nb.cells = cells
    meta = {}
    if "kernelspec" in solution_nb.metadata:
        meta["kernelspec"] = dict(solution_nb.metadata.kernelspec)
    lang = solution_nb.metadata.get("language_info", {})
    if lang.get("name"):
        # whole, as the kernel reports it: JupyterLab writes the kernel's language_info into a notebook it opens,
        # so a name alone opens every untouched notebook as modified (issue 29; jupyter/notebook issue 2123: a
        # Python of another version than the one that ran the solutions still does)
        meta["language_info"] = copy.deepcopy(dict(lang))
    nb.metadata = nbformat.from_dict(meta)
    return nb


def _writes(nb: NotebookNode) -> str:
    return nbformat.writes(nb, version=4) + "\n"  # nbformat.write adds the final newline too


def _render(sol_path: Path) -> str:
    return _writes(student_notebook(_read(sol_path), name=sol_path.name))


def generate_notebooks(solutions_dir, notebooks_dir) -> list[Path]:
    """Write the student notebook of every ``solutions_dir/*.ipynb`` into ``notebooks_dir``.

    Files are only rewritten when their content changes. Notebooks in ``notebooks_dir``
    without a source are left alone (:func:`check_notebooks` reports them).

    Returns
    -------
    list of Path
        The student notebooks, one per solution notebook, sorted by name.
    """
    notebooks_dir = Path(notebooks_dir)
    rendered = [(p, _render(p)) for p in _solution_paths(Path(solutions_dir))]  # fail before writing
    notebooks_dir.mkdir(parents=True, exist_ok=True)
    out = []
    for sol, text in rendered:
        target = notebooks_dir / sol.name
        if not target.exists() or target.read_text(encoding="utf-8") != text:
            target.write_text(text, encoding="utf-8")
        out.append(target)
    return out


def check_notebooks(solutions_dir, notebooks_dir) -> list[str]:
    """Differences between ``notebooks_dir`` and what :func:`generate_notebooks` would write.

    Returns
    -------
    list of str
        One human-readable line per problem; ``[]`` when in sync.
    """
    solutions_dir, notebooks_dir = Path(solutions_dir), Path(notebooks_dir)
    diffs = []
    sources = _solution_paths(solutions_dir)
    names = {p.name for p in sources}
    for sol in sources:
        target = notebooks_dir / sol.name
        if not target.exists():
            diffs.append(f"{target} is missing (source {sol})")
            continue
        want = _render(sol)
        have = target.read_text(encoding="utf-8")
        if have != want:
            diffs.append(f"{target} differs from the student version of {sol}: {_first_difference(have, want)}")
    if notebooks_dir.is_dir():
        for extra in sorted(notebooks_dir.glob("*.ipynb")):
            if extra.name not in names:
                diffs.append(f"{extra} has no source in {solutions_dir}; add {solutions_dir / extra.name} or delete it")
    return diffs


def _first_difference(have: str, want: str) -> str:
    try:
        a, b = nbformat.reads(have, as_version=4), nbformat.reads(want, as_version=4)
    except Exception:
        return "the file is not a valid notebook"
    if len(a.cells) != len(b.cells):
        return f"{len(a.cells)} cells instead of {len(b.cells)}"
    for i, (ca, cb) in enumerate(zip(a.cells, b.cells)):
        if ca != cb:
            fields = sorted(k for k in set(ca) | set(cb) if ca.get(k) != cb.get(k))
            return f"cell {i} differs in {', '.join(fields)}"
    if a.metadata != b.metadata:
        return "notebook metadata differs"
    return "formatting differs (edited by hand?)"


# --------------------------------------------------------------------------- release
def _skip(rel: Path) -> bool:
    return any(part in EXCLUDED_DIRS for part in rel.parts) or rel.name.endswith(EXCLUDED_SUFFIXES)


def _copy_tree(src: Path, dst: Path) -> None:
    for path in sorted(src.rglob("*")):
        rel = path.relative_to(src)
        if _skip(rel) or path.is_dir():
            continue
        (dst / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(path, dst / rel)


def _check_out_dir(out: Path, root: Path) -> None:
    if out == root or root.is_relative_to(out):
        raise DtscalError(f"the release folder {out} contains the kit checkout {root}; choose a new folder")
    for name in ("solutions", "notebooks", *RELEASE_TREES, "tests"):
        if out.is_relative_to(root / name):
            raise DtscalError(f"the release folder {out} is inside the kit's {name}/; choose a folder outside it")
    if out.exists():
        if not out.is_dir():
            raise DtscalError(f"{out} exists and is not a folder; choose a new folder for the release")
        if any(out.iterdir()) and not (out / RELEASE_MARKER).exists():
            raise DtscalError(
                f"{out} is not empty and was not written by `dtscal release`; choose a new or empty folder"
            )


def release(out_dir, repo_root=None) -> Path:
    """Write the student version of the course into ``out_dir``.

    This is the hand-out (``dtscal handout OUT``): a self-contained student course. It holds
    ``notebooks/`` (generated from ``solutions/``, never copied), ``dtscal_lib/`` and
    ``data/`` without grading-only folders (:data:`EXCLUDED_DIRS`) and caches,
    ``pyproject.toml`` (and ``LICENSE`` when present), the students' ``README.md`` and
    ``start.sh`` (:data:`STUDENT_README`, :data:`START_SH`), the files of :data:`RELEASE_EXTRA`
    (``scripts/install-ros.sh``, the TA page ``docs/ta.md``) and a ``.gitignore`` that keeps the
    student's ``workspace/`` in git (:data:`HANDOUT_GITIGNORE`). It holds no ``solutions/``, no
    ``grading/``, no ``tests/`` and no benchmarks. A folder written by an earlier release is replaced.
    After writing, the release is scanned for solution code (:func:`find_solution_leaks`); then it is
    made a git repository with one commit of everything in it, by :data:`HANDOUT_AUTHOR`.

    Returns
    -------
    Path
        ``out_dir``, resolved.

    Raises
    ------
    DtscalError
        If ``out_dir`` is unsafe (inside the checkout's sources, or a non-empty folder not
        written by a release) or a solution line leaked into the release.
    """
    from ..paths import repo_root as default_root

    root = Path(repo_root if repo_root is not None else default_root()).resolve()
    out = Path(out_dir).resolve()
    _check_out_dir(out, root)
    sources = _solution_paths(root / "solutions")
    rendered = [(p.name, _render(p)) for p in sources]  # fail on bad markers before touching out
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    (out / "notebooks").mkdir()
    for name, text in rendered:
        (out / "notebooks" / name).write_text(text, encoding="utf-8")
    for tree in RELEASE_TREES:
        if (root / tree).is_dir():
            _copy_tree(root / tree, out / tree)
    for f in RELEASE_FILES:
        if (root / f).is_file():
            shutil.copy2(root / f, out / f)
    (out / "README.md").write_text(STUDENT_README, encoding="utf-8")
    (out / "start.sh").write_text(START_SH, encoding="utf-8")
    (out / "start.sh").chmod(0o755)
    (out / ".gitignore").write_text(HANDOUT_GITIGNORE, encoding="utf-8")
    for f in RELEASE_EXTRA:
        if (root / f).is_file():
            for g in (f, *sourced_scripts(root, f)):
                (out / g).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(root / g, out / g)
                if g.endswith(".md"):
                    (out / g).write_text(handout_text((root / g).read_text(encoding="utf-8")), encoding="utf-8")
    (out / RELEASE_MARKER).write_text("written by `dtscal release`; safe to delete and regenerate\n")
    leaks = find_solution_leaks(out, sources)
    if leaks:
        raise DtscalError(
            "solution code leaked into the release (move it out of the library, or tag the cell "
            "'solution_only'):\n  " + "\n  ".join(leaks[:20])
        )
    _git_init(out)
    return out


#: a part of a kit page the hand-out leaves out: what needs the instructor's kit (its tests, benchmarks, the
#: grader, the hub's set-up scripts), which a hand-out reader could not run or find
KIT_ONLY_BEGIN, KIT_ONLY_END = "<!-- kit only -->", "<!-- /kit only -->"


def handout_text(text: str) -> str:
    """A kit page as the hand-out ships it: every ``<!-- kit only -->`` ... ``<!-- /kit only -->`` part left out.

    Raises
    ------
    DtscalError
        On a part that is opened and never closed, or closed without being opened.
    """
    kept, inside = [], False
    for n, line in enumerate(text.split("\n"), 1):
        mark = line.strip()
        if mark in (KIT_ONLY_BEGIN, KIT_ONLY_END):
            if (mark == KIT_ONLY_BEGIN) == inside:
                raise DtscalError(f"line {n}: {mark} {'inside' if inside else 'outside'} a kit-only part; "
                                  f"pair each {KIT_ONLY_BEGIN} with a {KIT_ONLY_END}")
            inside = not inside
        elif not inside:
            kept.append(line)
    if inside:
        raise DtscalError(f"a {KIT_ONLY_BEGIN} part is never closed; add {KIT_ONLY_END}")
    return re.sub(r"\n{3,}", "\n\n", "\n".join(kept))


#: ``source "$(dirname "$0")/x.sh"`` or ``. "$(dirname "$0")/x.sh"``: a script beside the script
_SOURCED = re.compile(r"""^\s*(?:source|\.)\s+["']?\$\(dirname\s+["']?\$0["']?\)/([\w./-]+?)["']?\s*(?:#.*)?$""",
                      re.M)


def sourced_scripts(root: Path, script: str) -> list[str]:
    """Every file ``script`` (a path relative to ``root``) sources from beside itself, and what those source."""
    if not script.endswith(".sh"):
        return []
    found: list[str] = []
    todo = [script]
    while todo:
        current = todo.pop()
        for name in _SOURCED.findall((root / current).read_text(encoding="utf-8")):
            rel = (Path(current).parent / name).as_posix()
            if not (root / rel).is_file():
                raise DtscalError(f"{current} sources {rel}, which the kit does not have; restore it (git checkout)")
            if rel not in found and rel != script:
                found.append(rel)
                todo.append(rel)
    return found


def _git_init(out: Path) -> None:
    """Make the hand-out a git repository with one commit of everything in it (what the README promises)."""
    import subprocess

    if shutil.which("git") is None:
        raise DtscalError("git is not installed: the hand-out is a git repository; install git "
                          "(sudo apt-get install git) and write the hand-out again")
    name, email = HANDOUT_AUTHOR
    env = {k: v for k, v in os.environ.items() if not k.startswith("GIT_")}
    env.update(GIT_AUTHOR_NAME=name, GIT_AUTHOR_EMAIL=email, GIT_COMMITTER_NAME=name, GIT_COMMITTER_EMAIL=email)
    opts = ["-c", "init.defaultBranch=main", "-c", "commit.gpgsign=false", "-c", "core.hooksPath=/dev/null"]
    for args in (["init", "-q"], ["add", "-A"], ["commit", "-q", "-m", "the course as handed out"]):
        res = subprocess.run(["git", *opts, *args], cwd=out, env=env, capture_output=True, text=True)
        if res.returncode != 0:
            raise DtscalError(f"git {args[0]} in {out} failed: {(res.stderr or res.stdout).strip()[:300]}; "
                              "fix git's set-up and write the hand-out again")


#: lines that only convert/validate inputs (``x = np.asarray(x, dtype=float).reshape(-1, 2)``):
#: every function starts with them, so finding one elsewhere proves nothing
_BOILERPLATE = re.compile(
    r"^[\w, ]+ = (np\.)?(asarray|array|atleast_2d|float|int)\((?:[^()]|\([^()]*\))*\)"
    r"(\.(reshape|ravel|copy|astype)\([^()]*\))*$"
)


def _distinctive(line: str) -> str | None:
    """A solution line worth searching for: not blank, not a comment, not tiny or boilerplate."""
    s = line.strip()
    if not s or s.startswith("#") or len(re.sub(r"\s", "", s)) < 20 or _BOILERPLATE.match(s):
        return None
    return s


def solution_lines(nb_paths: Iterable[Path]) -> list[tuple[str, str, str]]:
    """Distinctive code lines of every solution region: ``(notebook, function, line)``."""
    out = []
    for p in nb_paths:
        nb = _read(Path(p))
        for i, cell in enumerate(nb.cells):
            if cell.cell_type != "code":
                continue
            for func, lines in region_code(cell.source, _where(Path(p).name, i)).items():
                for line in lines:
                    s = _distinctive(line)
                    if s:
                        out.append((Path(p).name, func, s))
    return out


def find_solution_leaks(out_dir, solution_nbs: Iterable[Path]) -> list[str]:
    """Lines of solution regions found in any text file under ``out_dir``.

    Lines shorter than 20 non-blank characters and comments are not searched (they are
    too generic to prove a leak).

    Returns
    -------
    list of str
        ``"<file>: <notebook>:<function>: <line>"`` per hit; ``[]`` when clean.
    """
    lines = solution_lines(solution_nbs)
    hits = []
    for path in sorted(Path(out_dir).rglob("*")):
        if not path.is_file():
            continue
        try:
            text = path.read_text(encoding="utf-8")
        except (UnicodeDecodeError, OSError):
            continue
        text_lines = {l.strip() for l in text.split("\n")}
        if path.suffix == ".ipynb":  # sources are JSON strings: decode them
            try:
                nb = nbformat.reads(text, as_version=4)
                text_lines = {l.strip() for c in nb.cells for l in c.source.split("\n")}
            except Exception:
                pass
        for nb_name, func, s in lines:
            if s in text_lines:
                hits.append(f"{path}: {nb_name}:{func}: {s}")
    return hits


# --------------------------------------------------------------------------- using solutions
def _exec_source(source: str) -> str:
    """Cell source as plain Python: IPython magics and shell lines commented out."""
    return "\n".join(("# " + l) if l.lstrip().startswith(("%", "!")) else l for l in _lines(source))


def _defined_functions(source: str) -> list[str]:
    return [n.name for n in ast.parse(source).body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]


def solution_functions(nb_path, names: Iterable[str] | None = None) -> dict[str, Callable]:
    """The exercise functions of a solutions notebook (markers checked), ready to call.

    See :func:`notebook_functions`; this one also insists that every exercise cell holds a
    well-formed solution region.
    """
    return notebook_functions(nb_path, names, solutions=True)


def notebook_functions(nb_path, names: Iterable[str] | None = None, *,
                       solutions: bool = False) -> dict[str, Callable]:
    """The exercise functions of a course notebook (solution or student version), ready to call.

    Runs the cell tagged ``imports`` and every cell tagged ``exercise`` (in order) in a
    fresh namespace; the rest of the notebook is not run.

    Parameters
    ----------
    nb_path : path of a notebook in ``solutions/`` or ``notebooks/``
    names : optional, the functions wanted (default: every function the exercise cells define)

    Returns
    -------
    dict name -> function

    Raises
    ------
    DtscalError
        If the notebook has no ``imports``/``exercise`` cells, a cell fails to run, or a
        requested name is not defined by an exercise cell.
    """
    nb_path = Path(nb_path)
    nb = _read(nb_path)
    if solutions:
        _validate_cells(nb, nb_path.name)
    imports = [c for c in nb.cells if c.cell_type == "code" and IMPORTS_TAG in _tags(c)]
    exercises = [c for c in nb.cells if c.cell_type == "code" and EXERCISE_TAG in _tags(c)]
    if not imports or not exercises:
        raise DtscalError(
            f"{nb_path.name}: needs a code cell tagged 'imports' and cells tagged 'exercise' "
            f"(found {len(imports)} and {len(exercises)})"
        )
    module_name = "dtscal_solution_" + re.sub(r"\W", "_", nb_path.stem)
    ns: dict = {"__name__": module_name}
    defined = []
    for cell in imports + exercises:
        idx = nb.cells.index(cell)
        src = _exec_source(cell.source)
        try:
            code = compile(src, f"<{nb_path.name} cell {idx}>", "exec")
            if cell in exercises:
                defined += _defined_functions(src)
            with contextlib.redirect_stdout(io.StringIO()):  # setup prints are for the notebook reader
                exec(code, ns)
        except Exception as exc:
            raise DtscalError(f"{_where(nb_path.name, idx)} failed to run: {type(exc).__name__}: {exc}") from exc
    wanted = list(names) if names is not None else defined
    missing = [n for n in wanted if n not in defined]
    if missing:
        raise DtscalError(
            f"{nb_path.name} defines no exercise function named {', '.join(missing)}; "
            f"its exercise cells define {', '.join(defined) or 'nothing'}"
        )
    return {n: ns[n] for n in wanted}


def inject_solutions(student_nb: NotebookNode, solution_nb: NotebookNode) -> NotebookNode:
    """Paste the solution regions into a student notebook's stubs (as a student who solved it).

    Stubs are matched to regions by the name of the enclosing function. Returns a new
    notebook; the inputs are not modified.

    Raises
    ------
    DtscalError
        If a stub has no matching solution region.
    """
    solutions: dict[str, list[str]] = {}
    sol_name = _nb_name(solution_nb, "solution notebook")
    for i, cell in enumerate(solution_nb.cells):
        if cell.cell_type == "code":
            solutions.update(region_code(cell.source, _where(sol_name, i)))
    nb = copy.deepcopy(student_nb)
    for i, cell in enumerate(nb.cells):
        if cell.cell_type != "code":
            continue
        lines, out, func, j = _lines(cell.source), [], "", 0
        while j < len(lines):
            m = _DEF_RE.match(lines[j])
            if m:
                func = m.group(1)
            if lines[j].strip() == STUB_COMMENT and j + 1 < len(lines) and "NotImplementedError" in lines[j + 1]:
                if func not in solutions:
                    raise DtscalError(
                        f"student notebook cell {i}: no solution region for function {func or '(none)'}"
                    )
                out.extend(solutions[func])
                j += 2
                continue
            out.append(lines[j])
            j += 1
        cell.source = "\n".join(out)
    return nb


# --------------------------------------------------------------------------- maintaining solutions
#: the output of a displayed widget: a random model id per run, and no use without the live kernel
WIDGET_VIEW = "application/vnd.jupyter.widget-view+json"


def strip_widget_outputs(nb: NotebookNode) -> int:
    """Drop widget views (random ``model_id``) from stored outputs, keeping their text; returns how many.

    nbval does not compare widget views, and the widget state is not stored, so a view is only a
    model id that changes on every run (noise in every diff). The output's ``text/plain`` stays.
    """
    n = 0
    nb.metadata.pop("widgets", None)  # widget state is rebuilt when the notebook is opened
    for cell in nb.cells:
        for out in cell.get("outputs", []) if cell.cell_type == "code" else []:
            data = out.get("data")
            if data and WIDGET_VIEW in data:
                del data[WIDGET_VIEW]
                n += 1
                if not data:
                    data["text/plain"] = "a widget (shown when the notebook runs in JupyterLab)"
    return n


def coalesce_streams(nb: NotebookNode) -> int:
    """Join consecutive ``stdout`` (or ``stderr``) outputs of a cell into one; returns how many were joined.

    A kernel sends a printed line in one or several stream messages, depending on when its buffer is
    flushed (``print(..., end="")`` then ``print()`` can arrive as one output or two). nbval joins them
    before comparing; stored outputs joined the same way make a re-run's file independent of that timing.
    """
    n = 0
    for cell in nb.cells:
        if cell.cell_type != "code":
            continue
        merged = []
        for out in cell.get("outputs", []):
            prev = merged[-1] if merged else None
            if (out.get("output_type") == "stream" and prev is not None and prev.get("output_type") == "stream"
                    and prev.get("name") == out.get("name")):
                prev["text"] = prev.get("text", "") + out.get("text", "")
                n += 1
            else:
                merged.append(out)
        cell["outputs"] = merged
    return n


def execute_solutions(solutions_dir, names: Iterable[str] | None = None, *, timeout: int = 300,
                      progress: bool = False) -> list[Path]:
    """Run solution notebooks top to bottom and store their outputs (what nbval compares).

    Each notebook runs in its own folder, as JupyterLab and nbval run it. Per-cell execution
    timestamps and widget views (:func:`strip_widget_outputs`) are dropped and consecutive stream
    outputs joined (:func:`coalesce_streams`) so that re-running an
    unchanged notebook leaves the file unchanged wherever the outputs are deterministic.

    Parameters
    ----------
    solutions_dir : folder of solution notebooks
    names : optional file names (``02_homography.ipynb``) to run; default all
    progress : a line per notebook and a bar of its code cells on stderr
    """
    import sys

    from nbclient import NotebookClient

    paths = _solution_paths(Path(solutions_dir))
    if names:
        wanted = set(names)
        unknown = wanted - {p.name for p in paths}
        if unknown:
            raise DtscalError(f"no solution notebook named {', '.join(sorted(unknown))} in {solutions_dir}")
        paths = [p for p in paths if p.name in wanted]
    for k, path in enumerate(paths, 1):
        nb = _read(path)
        nb.metadata.pop("widgets", None)
        bar = None
        if progress:
            from tqdm import tqdm

            print(f"executing {path.name} ({k}/{len(paths)})", file=sys.stderr, flush=True)
            bar = tqdm(total=sum(c.cell_type == "code" for c in nb.cells), desc=path.stem, unit="cell",
                       file=sys.stderr, leave=False, disable=None)
        client = NotebookClient(nb, timeout=timeout, kernel_name="python3", store_widget_state=False,
                                resources={"metadata": {"path": str(path.parent)}})
        if bar is not None:
            client.on_cell_executed = lambda **_kw: bar.update(1)
        try:
            client.execute()
        except Exception as exc:
            raise DtscalError(f"{path.name} failed while executing; fix the notebook and run again: {exc}") from exc
        finally:
            if bar is not None:
                bar.close()
        for cell in nb.cells:
            cell.metadata.pop("execution", None)
        strip_widget_outputs(nb)
        coalesce_streams(nb)
        path.write_text(_writes(nb))
    return paths
