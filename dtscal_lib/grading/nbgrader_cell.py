"""The kit's grader inside an nbgrader autograded test cell (the course exported by ``dtscal release --nbgrader``).

nbgrader gives a test cell all its points unless it raises, or partial credit when the cell's last
expression is a number (``nbgrader.utils.determine_grade``: an ``execute_result`` cast to float). Each
exported test cell calls :func:`score` inside nbgrader's hidden-test markers with the hidden cases, the
tolerances and the reference functions it carries, and ends in the number it returns: the points the
kit's own grader (:func:`.grade.grade_file`, sandbox and all) gives that function for the code the kernel
ran, so nbgrader's score of a function is ``dtscal grade``'s. The student's code is taken from the
kernel's input history (the cells as nbgrader executed them), test cells left out.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import tempfile
from pathlib import Path

#: the first line of every exported test cell; cells holding it are not the student's code
MARK = "# dtscal autograded test"

_CACHE: dict[str, object] = {}


def _history() -> list[str]:
    from IPython import get_ipython

    ip = get_ipython()
    if ip is None:
        raise RuntimeError("dtscal's nbgrader test cells run inside a Jupyter kernel (nbgrader autograde)")
    return list(ip.user_ns.get("In", []))


def _grade(assignment: str, code: list[str], *, cases: dict, points: float, tolerances: dict,
           reference: str):
    import nbformat

    from .grade import grade_file
    from .material import Material

    with tempfile.TemporaryDirectory(prefix="dtscal-nbgrader-") as tmp:
        root = Path(tmp)
        (root / "grading").mkdir()
        (root / "solutions").mkdir()
        ref = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(reference)])
        nbformat.write(ref, str(root / "solutions" / f"{assignment}.ipynb"))
        sub = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(c) for c in code])
        (root / "work").mkdir()
        path = root / "work" / f"{assignment}.ipynb"
        nbformat.write(sub, str(path))
        material = Material(root, float(points), cases, tolerances=tolerances)
        return grade_file(path, material, assignment, student="nbgrader")


@contextlib.contextmanager
def _stderr_to_stdout():
    """nbgrader scores a test cell 0 if it wrote anything on stderr (``determine_grade``): what the grader or
    the processes it starts say there (a warning, say) is printed on stdout instead, after the grading."""
    import io
    import os
    import sys
    import warnings

    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as spill:
        os.dup2(spill.fileno(), 2)
        text = io.StringIO()
        try:
            with contextlib.redirect_stderr(text), warnings.catch_warnings():
                warnings.simplefilter("ignore")
                yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            spill.seek(0)
            said = text.getvalue() + spill.read().decode(errors="replace")
            if said.strip():
                print(said.strip()[-2000:])


def score(assignment: str, function: str, *, cases: dict, points: float, tolerances: dict, reference: str,
          cells: list[str] | None = None, show: bool = True) -> float:
    """Points of ``function`` (0 .. ``points``) for the code the kernel ran; prints why (stdout)."""
    code = [c for c in (cells if cells is not None else _history()) if c and c.strip() and MARK not in c]
    key = hashlib.sha256(json.dumps([assignment, code, cases, points, tolerances, reference],
                                    sort_keys=True, default=str).encode()).hexdigest()
    if key not in _CACHE:
        with _stderr_to_stdout():
            _CACHE[key] = _grade(assignment, code, cases=cases, points=points, tolerances=tolerances,
                                 reference=reference)
    res = _CACHE[key]
    fr = next(f for f in res.functions if f.name == function)
    if show:
        print(f"{function}: {fr.score:g} / {fr.max_score:g}")
        for t in fr.tests:
            line = f"  [{'x' if t.score >= t.max_score else ' '}] {t.name}: {t.score:g} / {t.max_score:g}"
            print(line + (f"\n      {t.output.splitlines()[0]}" if t.output and t.score < t.max_score else ""))
        if fr.diagnosis:
            print(f"  {fr.diagnosis}")
        for n in res.notes:
            if function in n:
                print(f"  {n}")
    return float(fr.score)
