"""Grade one submission (a notebook or a .py file) of one assignment.

Flow: parse the submission (:mod:`.loader`, nothing runs), refuse credit for functions
that call a solving routine, run the other functions' checks and the diagnosis probes in
the sandbox (:mod:`.sandbox`), judge the answers against the references computed here
(:mod:`.checks`), name the mistake (:mod:`dtscal_lib.selfcheck.diagnosis`).
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass, field
from pathlib import Path

from ..selfcheck import diagnosis
from .loader import Submission, load_submission, useful_import
from .material import ASSIGNMENTS, Material
from .sandbox import CPU_S, WALL_S, CheckRun, SandboxRun, run_calls, validate_limits

NOT_IMPLEMENTED = "not implemented (the function still raises NotImplementedError)"


@dataclass
class TestResult:
    """One check of one function, as Gradescope shows it."""

    name: str
    function: str
    score: float
    max_score: float
    output: str = ""

    def to_dict(self) -> dict:
        return {"name": f"{self.function}: {self.name}", "score": round(self.score, 2),
                "max_score": round(self.max_score, 2), "output": self.output, "visibility": "visible"}


@dataclass
class FunctionResult:
    name: str
    tests: list[TestResult] = field(default_factory=list)
    diagnosis: str = ""
    status: str = "graded"
    #: the named mistake behind ``diagnosis``: (key, what is wrong, equation to revisit)
    mistake: tuple | None = None

    @property
    def score(self) -> float:
        return round(sum(t.score for t in self.tests), 2)

    @property
    def max_score(self) -> float:
        return round(sum(t.max_score for t in self.tests), 2)


@dataclass
class GradeResult:
    """Everything graded in one submission file."""

    submission: str
    assignment: str
    student: str = ""
    functions: list[FunctionResult] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    execution_time: float = 0.0

    @property
    def score(self) -> float:
        return round(sum(f.score for f in self.functions), 2)

    @property
    def max_score(self) -> float:
        return round(sum(f.max_score for f in self.functions), 2)


def grade_file(path, material: Material, assignment: str, *, student: str = "",
               wall_s: float = WALL_S, cpu_s: int = CPU_S, mem_mb: int | None = None) -> GradeResult:
    """Grade one notebook or .py file against ``assignment``; never raises on student code."""
    validate_limits(wall_s, cpu_s, mem_mb)
    t0 = time.perf_counter()
    path = Path(path)
    res = GradeResult(str(path), assignment, student or path.stem)
    try:
        sub = load_submission(path)
    except Exception as exc:  # unreadable file: zero, with the reason
        sub = Submission(path)
        res.notes.append(f"the submission could not be read: {exc}")
    res.notes += [f"syntax error, cell skipped: {e}" for e in sub.syntax_errors]
    checks = material.checks(assignment)
    jobs, plan = [], {}
    for func in ASSIGNMENTS[assignment]:
        fr = FunctionResult(func)
        res.functions.append(fr)
        reason = ""
        if func not in sub.functions:
            reason = f"{func} is not defined in the submission"
            fr.status = "missing"
        elif func in sub.stubs:
            reason, fr.status = NOT_IMPLEMENTED, "not implemented"
        elif func in sub.forbidden:
            fr.status = "academic honesty"
            reason = (f"no credit: {func} calls {', '.join(sub.forbidden[func])}, which does the exercise for you. "
                      "Write the computation yourself (calling it from tests or plots is fine).")
        for b in checks[func]:
            fr.tests.append(TestResult(b.name, func, 0.0, b.weight, reason))
        if reason:
            continue
        for i, b in enumerate(checks[func]):
            cid = len(jobs)
            jobs.append({"id": cid, "calls": b.calls, "wall": wall_s, "cpu": cpu_s})
            plan[cid] = (fr, i, b)
        cid = len(jobs)
        probe = diagnosis.probe_args(func)
        jobs.append({"id": cid, "calls": [(func, a) for a in probe], "wall": wall_s, "cpu": cpu_s})
        plan[cid] = (fr, None, probe)
    honesty: dict[str, set] = {}
    if jobs:
        statements = [(useful_import(src), line) if src.lstrip().startswith(("import ", "from ")) else (src, line)
                      for src, line in sub.statements]
        statements = [st for st in statements if st[0] is not None]
        kw = {"mem_mb": mem_mb} if mem_mb else {}
        try:
            run = run_calls(statements, jobs, blocked_paths=material.blocked_paths, **kw)
        except Exception as exc:  # the sandbox itself failed: say so, grade the others
            run = SandboxRun(checks={j["id"]: CheckRun(failure=f"the grader could not run this submission: {exc}")
                                     for j in jobs})
            res.notes.append(f"the sandbox failed: {exc}")
        for k, err in run.load_errors:
            where = sub.where(statements[k][1]) if k < len(statements) else "?"
            res.notes.append(f"statement at {where} skipped: {_cell_lines(sub, err)}")
        for cid, (fr, i, b) in plan.items():
            cr = run.checks.get(cid, CheckRun(failure="not run"))
            if i is None:
                try:
                    _diagnose(fr, b, cr)
                except Exception:  # noqa: BLE001 - no diagnosis is better than no grade
                    fr.diagnosis = ""
                continue
            used = sorted({h for c in cr.calls for h in c.honesty})
            if used:
                honesty.setdefault(fr.name, set()).update(used)
            frac, msg = b.judge(b, cr)
            msg = _cell_lines(sub, msg)
            frac = min(1.0, max(0.0, float(frac)))
            printed = next((c.stdout for c in cr.calls if c.stdout.strip()), "")
            if printed and frac < 1:
                msg += f"\nprinted: {printed[:300]}" + (" ... (output truncated)" if len(printed) > 300 else "")
            fr.tests[i] = TestResult(b.name, fr.name, round(frac * b.weight, 4), b.weight, msg)
        for fr in res.functions:
            if honesty.get(fr.name):  # caught at run time: a route the syntax check missed
                names = ", ".join(sorted(honesty[fr.name]))
                fr.status = "academic honesty"
                why = (f"no credit: while it ran, {fr.name} called {names}, which does the exercise for you "
                       "(caught inside the sandbox). Write the computation yourself.")
                fr.tests = [TestResult(t.name, t.function, 0.0, t.max_score, why) for t in fr.tests]
                continue
            if fr.status == "graded" and all(t.output.startswith("not implemented") for t in fr.tests):
                fr.status = "not implemented"
    res.execution_time = time.perf_counter() - t0
    return res


def not_handed_in(assignment: str, material: Material, student: str) -> GradeResult:
    """Zero for every check of ``assignment``, each saying it was not handed in."""
    res = GradeResult("", assignment, student)
    for func, checks in material.checks(assignment).items():
        fr = FunctionResult(func, status="not handed in")
        fr.tests = [TestResult(b.name, func, 0.0, b.weight, f"{assignment} was not handed in") for b in checks]
        res.functions.append(fr)
    return res


def _cell_lines(sub: Submission, text: str) -> str:
    """``(line 48 in f)`` -> ``(code cell 3, line 5 in f)``: the line the student sees."""
    if not sub.cells:
        return text
    return re.sub(r"\(line (\d+) in ", lambda m: f"({sub.where(int(m.group(1)))} in ", text)


def _diagnose(fr: FunctionResult, probe: list, cr: CheckRun) -> None:
    if cr.failure or len(cr.calls) < len(probe):
        return
    outputs = [c.value if c.ok else RuntimeError(c.error) for c in cr.calls]
    mistake = diagnosis.diagnose(fr.name, probe, outputs)
    if mistake is not None:
        fr.diagnosis = mistake.line()
        fr.mistake = (str(getattr(mistake, "key", fr.diagnosis)), str(getattr(mistake, "text", fr.diagnosis)),
                      str(getattr(mistake, "equation", "")))
