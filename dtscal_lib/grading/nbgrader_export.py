"""``dtscal release --nbgrader OUT``: the course as an nbgrader course folder.

nbgrader (https://nbgrader.readthedocs.io) is the grader most Jupyter courses already run on their hub.
The export writes ``OUT/nbgrader_config.py`` and one assignment per notebook,
``OUT/source/<assignment>/<assignment>.ipynb``, from ``solutions/``:

* each ``exercise`` cell becomes an nbgrader *solution* cell; its ``### BEGIN SOLUTION`` /
  ``### END SOLUTION`` region is nbgrader's own marker, which ``nbgrader generate_assignment`` replaces
  with a stub;
* every other cell is *read-only* (locked), cells tagged ``solution_only`` are left out;
* each graded function gets one *autograded test* cell at the end, worth the points per function. Its
  hidden part (between ``### BEGIN HIDDEN TESTS`` and ``### END HIDDEN TESTS``, which nbgrader strips
  from the students' copy and restores when it autogrades) carries that notebook's hidden cases
  (``grading/cases.py``), the tolerances (``grading/tolerances.json``) and the reference functions, and
  calls :func:`dtscal_lib.grading.nbgrader_cell.score`; the cell ends in the number of points the kit's
  grader gives the function, which nbgrader takes as partial credit. nbgrader's score of a function is
  therefore ``dtscal grade``'s on the same code.

The course folder is the instructor's (``source/`` holds the solutions and hidden cases, like
``solutions/`` and ``grading/`` here); students receive ``release/`` from ``nbgrader generate_assignment``.
Autograding needs the kit installed in the environment nbgrader runs the notebooks in.
"""

from __future__ import annotations

import ast
import pprint
from pathlib import Path

import nbformat

from ..errors import DtscalError
from ..notebook_format import (BEGIN, END, EXERCISE_TAG, IMPORTS_TAG, PRACTICE_TAG, SOLUTION_ONLY_TAG, _read,
                               _solution_paths, _tags, _validate_cells, find_regions)

BEGIN_HIDDEN, END_HIDDEN = "### BEGIN HIDDEN TESTS", "### END HIDDEN TESTS"
SCHEMA_VERSION = 3
#: nbgrader runs each cell with a timeout (its default is 30 s); a notebook's slowest cell and the grading
#: of a notebook's functions (the sandbox, one process per check) take longer on a loaded machine
CELL_TIMEOUT_S = 600

CONFIG = f'''"""nbgrader configuration of the dtscal course (written by `dtscal release --nbgrader`)."""

c = get_config()  # noqa: F821 - nbgrader provides it
c.CourseDirectory.course_id = "dtscal"
# the notebooks' slowest cells and the kit's grader in each test cell outlast nbgrader's default 30 s
c.Execute.timeout = {CELL_TIMEOUT_S}
c.Execute.interrupt_on_timeout = True
'''


def _md(kind: str, grade_id: str, points: float | None = None, tags=None) -> dict:
    meta = {"grade": kind == "test", "grade_id": grade_id, "locked": kind != "solution",
            "schema_version": SCHEMA_VERSION, "solution": kind == "solution", "task": False}
    if points is not None:
        meta["points"] = points
    out = {"nbgrader": meta}
    if tags:
        out["tags"] = list(tags)
    return out


def _literal(value, what: str) -> str:
    text = pprint.pformat(value, width=110, sort_dicts=True)
    try:
        if ast.literal_eval(text) != value:
            raise ValueError("changed on the way")
    except (ValueError, SyntaxError) as exc:
        raise DtscalError(f"{what} cannot be written into a notebook as a Python literal ({exc}); keep "
                          "grading/cases.py to numbers, strings, tuples, lists and dicts") from None
    return text


def test_cell_source(assignment: str, function: str, *, points: float, cases: dict, tolerances: dict,
                     reference: str) -> str:
    from .nbgrader_cell import MARK

    return "\n".join([
        f"{MARK}: {function} ({points:g} points)",
        "# When your instructor grades, the kit's grader runs its hidden cases on your functions here and this",
        "# cell shows the points (partial credit) and why; until then it shows nothing: use the self-checks above.",
        "from dtscal_lib.grading.nbgrader_cell import score as _dtscal_score",
        "_points = None",
        BEGIN_HIDDEN,
        f"_points = _dtscal_score({assignment!r}, {function!r}, points={points!r},",
        "    cases=" + _literal(cases, "the hidden cases"),
        "    , tolerances=" + _literal(tolerances, "grading/tolerances.json"),
        "    , reference=" + repr(reference) + ")",
        END_HIDDEN,
        "_points",
    ])


def _reference_source(nb) -> str:
    """The imports cell and the exercise cells of a solution notebook: the reference functions."""
    cells = [c.source for c in nb.cells if c.cell_type == "code"
             and (IMPORTS_TAG in _tags(c) or EXERCISE_TAG in _tags(c))]
    # nbgrader finds its markers anywhere in a line, string literals too: the reference keeps none
    lines = [line for line in "\n\n".join(cells).splitlines() if line.strip() not in (BEGIN, END)]
    return "\n".join(lines) + "\n"


def source_notebook(nb, assignment: str, *, functions: tuple[str, ...], checks: dict, points: float,
                    tolerances: dict) -> nbformat.NotebookNode:
    """The nbgrader source notebook of one solution notebook (the input is not modified)."""
    _validate_cells(nb, assignment)
    cells = []
    for i, cell in enumerate(nb.cells):
        tags = _tags(cell)
        if SOLUTION_ONLY_TAG in tags:
            continue
        if cell.cell_type == "code":
            new = nbformat.v4.new_code_cell(cell.source)
            if EXERCISE_TAG in tags:
                find_regions(cell.source, f"{assignment}, cell {i}")  # balanced, nbgrader's own markers
                func = next((f for f in functions if f"def {f}(" in cell.source), f"exercise-{i}")
                new.metadata = nbformat.from_dict(_md("solution", f"solution_{func}", tags=tags))
            elif PRACTICE_TAG in tags:  # the student's own functions: a solution cell nbgrader clears, no points
                names = [func for _b, _e, func in find_regions(cell.source, f"{assignment}, cell {i}")]
                new.metadata = nbformat.from_dict(_md("solution", "practice_" + "_".join(names), tags=tags))
            else:
                new.metadata = nbformat.from_dict(_md("locked", f"cell_{i:02d}", tags=tags))
        elif cell.cell_type == "markdown":
            new = nbformat.v4.new_markdown_cell(cell.source)
            if cell.get("attachments"):
                new.attachments = cell.attachments
            new.metadata = nbformat.from_dict(_md("locked", f"cell_{i:02d}", tags=tags))
        else:
            new = nbformat.v4.new_raw_cell(cell.source)
            new.metadata = nbformat.from_dict(_md("locked", f"cell_{i:02d}", tags=tags))
        cells.append(new)
    if functions:
        reference = _reference_source(nb)
        cases = {f: checks[f] for f in functions}
        head = nbformat.v4.new_markdown_cell(
            "## Autograded tests\n\nOne cell per function you wrote, worth "
            f"{points:g} points each. They run the course's hidden cases when your instructor grades "
            "(nbgrader's autograde); do not change or delete them.")
        head.metadata = nbformat.from_dict(_md("locked", "autograded_tests"))
        cells.append(head)
        for f in functions:
            source = test_cell_source(assignment, f, points=points, cases=cases, tolerances=tolerances,
                                      reference=reference)
            hidden = source.split(BEGIN_HIDDEN, 1)[1].split(END_HIDDEN, 1)[0]
            stray = [m for m in (BEGIN, END, BEGIN_HIDDEN, END_HIDDEN, "BEGIN SOLUTION", "END SOLUTION",
                                 "BEGIN HIDDEN TESTS", "END HIDDEN TESTS") if m in hidden]
            if stray:
                raise DtscalError(f"{assignment}: the hidden cases or reference of {f} hold nbgrader's marker "
                                  f"{stray[0]!r}, which nbgrader would take for its own; remove it from the text")
            test = nbformat.v4.new_code_cell(source)
            test.metadata = nbformat.from_dict(_md("test", f"test_{f}", points=points))
            cells.append(test)
    out = nbformat.v4.new_notebook(cells=cells)
    out.metadata = nbformat.from_dict({k: nb.metadata[k] for k in ("kernelspec", "language_info")
                                       if k in nb.metadata})
    return out


def export(out_dir, repo_root=None) -> list[Path]:
    """Write the nbgrader course into ``out_dir``; the notebooks written."""
    try:
        from .material import ASSIGNMENTS, Material
    except ImportError:  # a student's hand-out has no grader
        raise DtscalError("the nbgrader export runs in the instructor's kit (it needs grading/ and solutions/); "
                          "this copy of the kit has no grader") from None

    material = Material.load(repo_root)
    root = material.root
    out = Path(out_dir)
    if out.exists() and any(out.iterdir()) and not (out / "nbgrader_config.py").is_file():
        raise DtscalError(f"{out} exists and is not an nbgrader course written by the kit (no nbgrader_config.py); "
                          "give an empty or new folder")
    checks, points, tolerances = material.specs, material.points, material.tolerances
    written = []
    for sol in _solution_paths(root / "solutions"):
        nb = _read(sol)
        if not any(BEGIN in c.source for c in nb.cells if c.cell_type == "code") and sol.stem in ASSIGNMENTS:
            raise DtscalError(f"{sol}: no '{BEGIN}' region; the solutions are the source of the export")
        name = sol.stem
        src = source_notebook(nb, name, functions=ASSIGNMENTS.get(name, ()), checks=checks, points=points,
                              tolerances=tolerances)
        dest = out / "source" / name / f"{name}.ipynb"
        dest.parent.mkdir(parents=True, exist_ok=True)
        nbformat.write(src, str(dest))
        written.append(dest)
    (out / "nbgrader_config.py").write_text(CONFIG)
    return written
