"""Grades as people and tools read them: a table on stdout, Gradescope's results.json, a CSV."""

from __future__ import annotations

import csv
import json
import os
import tempfile
from pathlib import Path

from .grade import GradeResult
from .material import ASSIGNMENTS


def text(res: GradeResult) -> str:
    """Per-function block: diagnosis first (one line), then the checks with points and feedback."""
    lines = [f"{res.student} - {res.assignment}: {res.score:g} / {res.max_score:g} points "
             f"({res.execution_time:.1f} s)"]
    lines += [f"  note: {n}" for n in res.notes]
    for f in res.functions:
        lines.append(f"  {f.name}: {f.score:g} / {f.max_score:g}" + (f"  [{f.status}]" if f.status != "graded" else ""))
        if f.status in ("not implemented", "missing", "academic honesty"):
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
    notes on the student's files that were not graded (and why)."""
    tests, out = [], list(notes)
    for res in results:
        out += [f"{res.assignment}: {n}" for n in res.notes]
        for f in res.functions:
            for t in f.tests:
                d = t.to_dict()
                d["name"] = f"{res.assignment} / {d['name']}" if len(results) > 1 else d["name"]
                extra = f.diagnosis if f.diagnosis and t.score < t.max_score else ""
                d["output"] = "\n".join(x for x in (extra, d["output"]) if x)
                tests.append(d)
    return {
        "score": round(sum(r.score for r in results), 2),
        "execution_time": round(sum(r.execution_time for r in results), 2),
        "output": "\n".join(out) if out else f"graded {len(results)} notebook(s) with dtscal grade",
        "tests": tests,
    }


def write_json(path, obj) -> Path:
    """Write ``obj`` atomically (a reader never sees half a file)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    with os.fdopen(fd, "w") as f:
        json.dump(obj, f, indent=1)
    os.replace(tmp, path)
    return path


def write_csv(path, by_student: dict[str, list[GradeResult]], notes: dict | None = None) -> Path:
    """One row per student (also those with nothing graded), one column per graded function,
    then total, maximum (the class's: the same for everyone) and the notes on that student's files."""
    notes = notes or {}
    funcs = [f for a, fs in ASSIGNMENTS.items() for f in fs
             if any(r.assignment == a for rs in by_student.values() for r in rs)]
    maximum = 0.0
    for rs in by_student.values():
        maximum = max(maximum, sum(r.max_score for r in rs))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["student", *funcs, "total", "max", "notes"])
        for student in sorted(by_student):
            scores = {f.name: f.score for r in by_student[student] for f in r.functions}
            total = sum(r.score for r in by_student[student])
            extra = [f"{r.assignment}: {n}" for r in by_student[student] for n in r.notes]
            w.writerow([student, *[f"{scores.get(f, 0):g}" for f in funcs], f"{total:g}", f"{maximum:g}",
                        "; ".join([*notes.get(student, []), *extra])])
    return path
