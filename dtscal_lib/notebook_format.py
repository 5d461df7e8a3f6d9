"""The format of the kit's notebooks: solution regions, cell tags, reading a notebook.

Shared by the teaching wing (``teaching/release.py`` makes the student notebooks) and the grading wing
(``grading/nbgrader_export.py`` makes the nbgrader course); neither imports the other.
"""

from __future__ import annotations

import re
from pathlib import Path

import nbformat
from nbformat import NotebookNode

from .errors import DtscalError

BEGIN = "### BEGIN SOLUTION"
END = "### END SOLUTION"
EXERCISE_TAG, IMPORTS_TAG, SOLUTION_ONLY_TAG = "exercise", "imports", "solution_only"
#: cells whose solution regions the student writes for practice (stubbed, self-checked, never graded)
PRACTICE_TAG = "practice"
#: the tags of cells that may hold solution regions
REGION_TAGS = (EXERCISE_TAG, PRACTICE_TAG)

_DEF_RE = re.compile(r"^\s*def\s+([A-Za-z_]\w*)\s*\(")


# --------------------------------------------------------------------------- regions
def _lines(source: str) -> list[str]:
    return source.split("\n")


def _is_marker(line: str, marker: str) -> bool:
    return line.strip() == marker


def _where(nb_name: str, index: int) -> str:
    return f"{nb_name}, cell {index}"


def find_regions(source: str, where: str = "cell", *, begin: str = BEGIN,
                 end: str = END) -> list[tuple[int, int, str]]:
    """Solution regions of one cell's source (or other ``begin`` ... ``end`` regions).

    Parameters
    ----------
    source : str
        The cell's code.
    where : str
        Names the notebook and cell in error messages.

    Returns
    -------
    list of (begin_line, end_line, function_name)
        0-based line numbers of the two markers and the name of the nearest ``def``
        above the region (``""`` when there is none).

    Raises
    ------
    DtscalError
        On a ``BEGIN`` without ``END``, an ``END`` without ``BEGIN``, or nested regions.
    """
    BEGIN, END = begin, end  # noqa: N806 (the messages name the markers in use)
    regions, opened, func = [], None, ""
    for i, line in enumerate(_lines(source)):
        m = _DEF_RE.match(line)
        if m and opened is None:
            func = m.group(1)
        if _is_marker(line, BEGIN):
            if opened is not None:
                raise DtscalError(
                    f"{where}: '{BEGIN}' on line {i + 1} before the region opened on line {opened + 1} "
                    f"was closed; add '{END}' after the code"
                )
            opened = i
        elif _is_marker(line, END):
            if opened is None:
                raise DtscalError(
                    f"{where}: '{END}' on line {i + 1} has no matching '{BEGIN}' above it; "
                    "add the BEGIN marker or delete the stray END"
                )
            regions.append((opened, i, func))
            opened = None
        elif BEGIN.lstrip("# ") in line or END.lstrip("# ") in line:
            raise DtscalError(
                f"{where}: line {i + 1} mentions a marker but is not exactly "
                f"'{BEGIN}' or '{END}' on a line of its own: {line.strip()!r}"
            )
    if opened is not None:
        raise DtscalError(
            f"{where}: '{BEGIN}' on line {opened + 1} is never closed; add '{END}' after the code"
        )
    return regions


def _tags(cell) -> list[str]:
    return list(cell.get("metadata", {}).get("tags", []))


def _validate_cells(nb: NotebookNode, name: str) -> None:
    for i, cell in enumerate(nb.cells):
        src = cell.source
        if cell.cell_type != "code":
            if any(_is_marker(l, BEGIN) or _is_marker(l, END) for l in _lines(src)):
                raise DtscalError(
                    f"{_where(name, i)}: solution markers in a {cell.cell_type} cell; "
                    "regions belong in code cells tagged 'exercise'"
                )
            continue
        regions = find_regions(src, _where(name, i))
        if EXERCISE_TAG in _tags(cell) and len(regions) != 1:
            raise DtscalError(
                f"{_where(name, i)}: an 'exercise' cell must hold exactly one solution region "
                f"('{BEGIN}' ... '{END}'), found {len(regions)}"
            )
        if PRACTICE_TAG in _tags(cell) and not regions:
            raise DtscalError(f"{_where(name, i)}: a 'practice' cell must hold a solution region "
                              f"('{BEGIN}' ... '{END}'), found none")
        if regions and not any(t in _tags(cell) for t in REGION_TAGS):
            raise DtscalError(
                f"{_where(name, i)}: a solution region outside an 'exercise' or 'practice' cell; tag the cell "
                "'exercise' (graded) or 'practice' (not graded) in cell.metadata.tags so the tools can find it"
            )


def _read(path: Path) -> NotebookNode:
    try:
        return nbformat.read(str(path), as_version=4)
    except Exception as exc:
        raise DtscalError(f"cannot read notebook {path}: {exc}; is it valid nbformat 4 JSON?") from None


def _solution_paths(solutions_dir: Path) -> list[Path]:
    solutions_dir = Path(solutions_dir)
    if not solutions_dir.is_dir():
        raise DtscalError(f"no solutions folder at {solutions_dir}; run from the kit checkout or pass --repo")
    return sorted(p for p in solutions_dir.glob("*.ipynb") if not p.name.startswith("."))
