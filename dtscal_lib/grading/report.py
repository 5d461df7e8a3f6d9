"""Grades as people and tools read them: a table on stdout, Gradescope's results.json, a CSV."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

from .. import safe_write

from .errors import GRADER_ERROR
from .grade import GRADER_ERROR_STATUS, GradeResult
from .material import ASSIGNMENTS

#: a spreadsheet reads a cell starting with one of these as a formula (or, for tab and CR, as the
#: start of another cell): OWASP's "CSV Injection" page prescribes a leading single quote
FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def csv_cell(value: str) -> str:
    """``value`` safe in a spreadsheet: a leading ``'`` when it would be read as a formula (OWASP)."""
    value = str(value)
    return "'" + value if value.startswith(FORMULA_START) else value


def grader_errors(by_student: dict[str, list[GradeResult]]) -> list[str]:
    """The students with a function the grader could not run (to rerun), sorted."""
    return sorted(s for s, rs in by_student.items() if any(r.grader_error for r in rs))


def text(res: GradeResult) -> str:
    """Per-function block: diagnosis first (one line), then the checks with points and feedback."""
    lines = [f"{res.student} - {res.assignment}: {res.score:g} / {res.max_score:g} points "
             f"({res.execution_time:.1f} s)"]
    lines += [f"  note: {n}" for n in res.notes]
    for f in res.functions:
        lines.append(f"  {f.name}: {f.score:g} / {f.max_score:g}" + (f"  [{f.status}]" if f.status != "graded" else ""))
        if f.status in ("not implemented", "missing", "academic honesty", "not allowed", GRADER_ERROR_STATUS):
            lines.append(f"      {f.tests[0].output}")
            continue
        if f.diagnosis:
            lines.append(f"      {f.diagnosis}")
        for t in f.tests:
            mark = "ok  " if t.score >= t.max_score - 1e-9 else "FAIL"
            lines.append(f"      {mark} {t.score:5.2f}/{t.max_score:<5.2f} {t.name}")
            if t.output and mark == "FAIL":
                lines.extend(f"             {ln}" for ln in t.output.split("\n"))
    return "\n".join(lines)


def gradescope(results: list[GradeResult], notes: list[str] = ()) -> dict:
    """Gradescope's ``results.json`` for one student (one or several notebooks), with the
    notes on the student's files that were not graded (and why).

    Gradescope's format (gradescope-autograders.readthedocs.io, "Autograder Specifications"):
    a top-level ``score`` is "optional, but required if not on each test case". A check the
    grader could not run carries no ``score`` (nor ``max_score``: ``extra_data`` keeps it), and
    then the run carries none either: it is no grade at all, and ``extra_data.autograder_failed``
    marks it. The bundle's ``run_autograder`` then withholds ``results.json``, which Gradescope
    shows as "The autograder failed to execute correctly" (its "Troubleshooting" page), never 0."""
    tests, out = [], list(notes)
    failed = any(r.grader_error for r in results)
    if failed:
        out.insert(0, f"{GRADER_ERROR}: the grader itself failed on part of this submission (not your code); "
                      "those checks are not graded yet and will be graded when the instructor reruns them")
    if not results:
        out.insert(0, "The autograder could not grade this submission: it holds no course notebook. Upload your "
                      "notebook(s) under their course names (for example 01_pinhole_projection.ipynb) or the zip "
                      "`dtscal handin` wrote.")
    for res in results:
        out += [f"{res.assignment}: {n}" for n in res.notes]
        for f in res.functions:
            for t in f.tests:
                d = t.to_dict()
                d["name"] = f"{res.assignment} / {d['name']}" if len(results) > 1 else d["name"]
                extra = f.diagnosis if f.diagnosis and t.score < t.max_score else ""
                d["output"] = "\n".join(x for x in (extra, d["output"]) if x)
                if f.status == GRADER_ERROR_STATUS:  # not a 0 of the student's: no score at all
                    del d["score"]
                    d["extra_data"] = {"status": GRADER_ERROR_STATUS, "max_score": d.pop("max_score")}
                tests.append(d)
    return {
        **({"extra_data": {"status": GRADER_ERROR_STATUS, "autograder_failed": True}} if failed else
           {"score": round(sum(r.score for r in results), 2)}),
        "execution_time": round(sum(r.execution_time for r in results), 2),
        "output": "\n".join(out) if out else f"graded {len(results)} notebook(s) with dtscal grade",
        "tests": tests,
    }


def write_json(path, obj) -> Path:
    """Write ``obj`` atomically (a reader never sees half a file; a device is written through,
    never replaced: :mod:`dtscal_lib.safe_write`)."""
    return safe_write.write_text(path, json.dumps(obj, indent=1), what="results JSON")


def write_csv(path, by_student: dict[str, list[GradeResult]], notes: dict | None = None) -> Path:
    """One row per student (also those with nothing graded), one column per graded function,
    then total, maximum (the class's: the same for everyone) and the notes on that student's files.

    A function the grader could not run reads ``grader error`` (and the total ``grader error``
    too: it is not known yet), never 0. Text cells are escaped against formula injection
    (:func:`csv_cell`)."""
    notes = notes or {}
    funcs = [f for a, fs in ASSIGNMENTS.items() for f in fs
             if any(r.assignment == a for rs in by_student.values() for r in rs)]
    maximum = 0.0
    for rs in by_student.values():
        maximum = max(maximum, sum(r.max_score for r in rs))
    buf = io.StringIO(newline="")
    w = csv.writer(buf)
    w.writerow(["student", *funcs, "total", "max", "notes"])
    for student in sorted(by_student):
        cells = {f.name: (GRADER_ERROR_STATUS if f.status == GRADER_ERROR_STATUS else f"{f.score:g}")
                 for r in by_student[student] for f in r.functions}
        total = sum(r.score for r in by_student[student])
        failed = any(r.grader_error for r in by_student[student])
        extra = [f"{r.assignment}: {n}" for r in by_student[student] for n in r.notes]
        w.writerow([csv_cell(student), *[cells.get(f, "0") for f in funcs],
                    GRADER_ERROR_STATUS if failed else f"{total:g}", f"{maximum:g}",
                    csv_cell("; ".join([*notes.get(student, []), *extra]))])
    return safe_write.write_text(path, buf.getvalue(), what="class CSV")
