"""The instructor's view of a class: ``dtscal grade CLASS/ --report DIR`` writes ``DIR/index.html``.

One self-contained page (no script, no network): the score distribution of every graded
function (how many students in each band of its points), and the class's most frequent
named mistakes: what is wrong, how many students made it, who, and the equation of the
activity text to revisit in class. Students with nothing graded and files that were not
graded are listed too, so the page loses no one.
"""

from __future__ import annotations

import html
from pathlib import Path

from .. import safe_write
from .errors import GRADER_ERROR
from .grade import GRADER_ERROR_STATUS, GradeResult
from .material import ASSIGNMENTS

#: score bands, as fractions of a function's points: [lo, hi)
BANDS = [(0.0, 1e-9, "0"), (1e-9, 0.5, "< 50 %"), (0.5, 0.8, "50-80 %"), (0.8, 1.0 - 1e-9, "80-99 %"),
         (1.0 - 1e-9, 2.0, "full")]


def _e(x) -> str:
    return html.escape(str(x))


def summarize(by_student: dict[str, list[GradeResult]]) -> tuple[dict, list[dict]]:
    """Per function: the count of students in each band (and the mean); the named mistakes,
    most frequent first: ``{key, text, equation, function, students}``."""
    dist: dict[str, dict] = {}
    mistakes: dict[tuple, dict] = {}
    order = [f for fs in ASSIGNMENTS.values() for f in fs]
    for student, results in sorted(by_student.items()):
        for r in results:
            for f in r.functions:
                if f.status == GRADER_ERROR_STATUS:  # not graded yet: in no band (listed apart, see render)
                    continue
                d = dist.setdefault(f.name, {"bands": [0] * len(BANDS), "scores": [], "max": f.max_score})
                frac = f.score / f.max_score if f.max_score else 0.0
                d["bands"][next(i for i, (lo, hi, _) in enumerate(BANDS) if lo <= frac < hi)] += 1
                d["scores"].append(f.score)
                named = None
                if f.mistake:
                    named = f.mistake
                elif f.status == "academic honesty":
                    named = ("academic-honesty", "called a routine that does the exercise (OpenCV or the kit)",
                             "write the computation yourself")
                if named:
                    m = mistakes.setdefault((f.name, named[0]), {"key": named[0], "text": named[1],
                                                                  "equation": named[2], "function": f.name,
                                                                  "students": []})
                    if student not in m["students"]:
                        m["students"].append(student)
    dist = {f: dist[f] for f in sorted(dist, key=lambda f: order.index(f) if f in order else 99)}
    ranked = sorted(mistakes.values(), key=lambda m: (-len(m["students"]), m["function"], m["key"]))
    return dist, ranked


def render(by_student: dict[str, list[GradeResult]], notes: dict | None = None) -> str:
    """The page, as HTML text."""
    notes = notes or {}
    dist, ranked = summarize(by_student)
    n = len(by_student)
    # a student with a function the grader could not run has no total yet: not in the mean
    totals = [sum(r.score for r in rs) for rs in by_student.values() if not any(r.grader_error for r in rs)]
    maximum = max((sum(r.max_score for r in rs) for rs in by_student.values()), default=0)
    rows = []
    for f, d in dist.items():
        mean = sum(d["scores"]) / len(d["scores"]) if d["scores"] else 0.0
        cells = "".join(
            f'<td class="band"><div class="bar" style="width:{100 * c / max(n, 1):.0f}%"></div>{c}</td>'
            for c in d["bands"])
        rows.append(f"<tr><th scope='row'>{_e(f)}</th>{cells}<td>{mean:.1f} / {d['max']:g}</td></tr>")
    heads = "".join(f"<th scope='col'>{_e(b[2])}</th>" for b in BANDS)
    mrows = [f"<tr><td>{_e(m['text'])}</td><td>{_e(m['function'])}</td><td class='count'>{len(m['students'])}"
             f"</td><td>{_e(', '.join(m['students']))}</td><td>{_e(m['equation'])}</td></tr>" for m in ranked]
    if not mrows:
        mrows = ["<tr><td colspan='5'>no named mistake in this class</td></tr>"]
    nrows = [f"<tr><td>{_e(s)}</td><td>{_e(x)}</td></tr>" for s in sorted(notes) for x in notes[s]]
    erows = [f"<tr><td>{_e(s)}</td><td>{_e(f.name)}</td><td>{_e(r.grader_error)}</td></tr>"
             for s, rs in sorted(by_student.items()) for r in rs for f in r.functions
             if f.status == GRADER_ERROR_STATUS]
    errors = "" if not erows else f"""<h2>{_e(GRADER_ERROR)}</h2>
<p>The grader itself failed on these functions (not the students' code): they have no score yet, and the
totals of these students are incomplete. Rerun them.</p>
<table id="grader-errors"><thead><tr><th scope="col">student</th><th scope="col">function</th>
<th scope="col">what failed</th></tr></thead><tbody>{''.join(erows)}</tbody></table>
"""
    mean_total = sum(totals) / len(totals) if totals else 0.0
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>dtscal grade: class report</title>
<style>
body {{ font-family: sans-serif; margin: 2em; max-width: 70em; }}
table {{ border-collapse: collapse; margin-bottom: 2em; }}
th, td {{ border: 1px solid #bbb; padding: 0.3em 0.6em; text-align: left; vertical-align: top; }}
td.band {{ position: relative; min-width: 6em; }}
.bar {{ position: absolute; left: 0; top: 0; bottom: 0; background: #56B4E9; z-index: -1; }}
</style></head><body>
<h1>Class report</h1>
<p id="summary">{n} student(s); mean total {mean_total:.1f} / {maximum:g} points{
    "" if len(totals) == n else f" over the {len(totals)} fully graded"}.</p>
{errors}<h2>Score distribution per function</h2>
<p>Number of students whose points on the function fall in each band.</p>
<table id="distribution"><thead><tr><th scope="col">function</th>{heads}<th scope="col">mean</th></tr></thead>
<tbody>{''.join(rows)}</tbody></table>
<h2>Most frequent mistakes</h2>
<p>Named by the grader's diagnosis; revisit the equation in class.</p>
<table id="mistakes"><thead><tr><th scope="col">mistake</th><th scope="col">function</th>
<th scope="col">students</th><th scope="col">who</th><th scope="col">equation to revisit</th></tr></thead>
<tbody>{''.join(mrows)}</tbody></table>
<h2>Files not graded, work not handed in</h2>
<table id="notes"><thead><tr><th scope="col">student</th><th scope="col">note</th></tr></thead>
<tbody>{''.join(nrows) or "<tr><td colspan='2'>none</td></tr>"}</tbody></table>
</body></html>
"""


def write_report(folder, by_student: dict[str, list[GradeResult]], notes: dict | None = None) -> Path:
    """Write ``folder/index.html`` atomically; returns its path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    page = folder / "index.html"
    return safe_write.write_text(page, render(by_student, notes), what="class report", mode=0o644)
