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
from . import substitutes
from .loader import Submission, _called_names, load_submission, useful_import
from .material import ASSIGNMENTS, Material
from .sandbox import CPU_S, GRADER_ERROR, WALL_S, CheckRun, GraderError, SandboxRun, run_calls, validate_limits

NOT_IMPLEMENTED = "not implemented (the function still raises NotImplementedError)"
FORM_GATED = ("no points for form yet: none of this function's answers is right on any case, and checks of form "
              "(dtype, shape, inputs untouched, raising, H[2, 2] = 1) count only once the values are right on at "
              "least one case")


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
    stand_ins: dict[str, list[str]] = {}
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
        callees = exercise_callees(sub, func, ASSIGNMENTS[assignment])
        if callees:
            stand_ins[func] = callees
        for i, b in enumerate(checks[func]):
            cid = len(jobs)
            jobs.append({"id": cid, "calls": b.calls, "wall": wall_s, "cpu": cpu_s})
            plan[cid] = (fr, i, b, "own")
        cid = len(jobs)
        probe = diagnosis.probe_args(func)
        jobs.append({"id": cid, "calls": [(func, a) for a in probe], "wall": wall_s, "cpu": cpu_s})
        plan[cid] = (fr, None, probe, "own")
    honesty: dict[str, set] = {}
    judged: dict[tuple[str, int], dict[str, tuple[float, str]]] = {}
    if jobs:
        statements = [(useful_import(src), line) if src.lstrip().startswith(("import ", "from ")) else (src, line)
                      for src, line in sub.statements]
        statements = [st for st in statements if st[0] is not None]
        kw = {"mem_mb": mem_mb} if mem_mb else {}
        run = _sandbox(statements, jobs, material, kw, res)
        for k, err in run.load_errors:
            where = sub.where(statements[k][1]) if k < len(statements) else "?"
            res.notes.append(f"statement at {where} skipped: {_cell_lines(sub, err)}")
        _judge(run, plan, judged, honesty, sub)
        # one bug, one charge: a function whose callee lost points runs again with the grader's stand-in
        # for the callee (a second, smaller sandbox run, only for those functions); the better result counts
        lost = {fr.name for fr in res.functions if fr.status != "graded" or fr.diagnosis or any(
            judged.get((fr.name, i), {}).get("own", (0.0,))[0] < 1 for i in range(len(checks[fr.name])))}
        again = {f: cs for f, cs in stand_ins.items() if set(cs) & lost}
        if again:
            jobs2, plan2 = [], {}
            for fr in res.functions:
                if fr.name not in again:
                    continue
                subst = [substitutes.source(c) for c in again[fr.name]]
                n = len(checks[fr.name])
                jobs2.append({"id": len(jobs2), "calls": [c for b in checks[fr.name] for c in b.calls],
                              "wall": wall_s * n, "cpu": cpu_s * n, "substitute": subst})
                plan2[len(jobs2) - 1] = (fr, -1, checks[fr.name], "stand-in")
                probe = diagnosis.probe_args(fr.name)
                jobs2.append({"id": len(jobs2), "calls": [(fr.name, a) for a in probe], "wall": wall_s,
                              "cpu": cpu_s, "substitute": subst})
                plan2[len(jobs2) - 1] = (fr, None, probe, "stand-in")
                fr.diagnosis, fr.mistake = "", None  # the diagnosis of this function alone, with the stand-in
            _judge(_sandbox(statements, jobs2, material, kw, res), plan2, judged, honesty, sub)
        value_right: dict[str, bool] = {}
        own_points: dict[str, list] = {}
        for fr in res.functions:
            for i, b in enumerate(checks[fr.name]):
                if (fr.name, i) not in judged:
                    continue
                frac, msg = _one_charge(judged[(fr.name, i)], b.weight, again.get(fr.name, []))
                own = judged[(fr.name, i)].get("own", (0.0,))[0]
                own_points.setdefault(fr.name, [0.0, 0.0, False])  # value points, form points, a value right
                own_points[fr.name][1 if b.form else 0] += own * b.weight
                own_points[fr.name][2] |= not b.form and own > 0
                fr.tests[i] = TestResult(b.name, fr.name, round(frac * b.weight, 4), b.weight, msg)
                value_right.setdefault(fr.name, False)
                value_right[fr.name] |= not b.form and frac > 0
        for fr in res.functions:  # form gives points only to a function that computes something right
            if fr.status == "graded" and not value_right.get(fr.name, False):
                for i, b in enumerate(checks[fr.name]):
                    if b.form and fr.tests[i].score > 0:
                        fr.tests[i] = TestResult(b.name, fr.name, 0.0, b.weight, FORM_GATED)
        for fr in res.functions:  # one bug, one charge: say how the callee was treated
            if fr.name not in stand_ins or fr.status != "graded":
                continue
            who = _names(stand_ins[fr.name])
            if fr.name not in again:
                res.notes.append(f"{fr.name} calls {who}, which passes all its checks: graded with yours.")
                continue
            value, form, right = own_points.get(fr.name, [0.0, 0.0, False])
            own = value + (form if right else 0.0)
            changed = f"With your own {who}, {fr.name} would score {own:.4g} / {fr.max_score:g} instead of " \
                      f"{fr.score:g}." if abs(own - fr.score) > 1e-9 else f"Your own {who} gives it the same score."
            res.notes.append(f"{fr.name} calls {who}, which lost points: graded with the grader's {who} in place of "
                             f"yours and with yours, the better counts, so a mistake in {who} is charged there "
                             f"only. {changed}")
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
            if fr.status == "graded" and any(GRADER_ERROR in t.output for t in fr.tests):
                fr.status = GRADER_ERROR
    res.execution_time = time.perf_counter() - t0
    return res


def _sandbox(statements, jobs, material: Material, kw: dict, res: GradeResult) -> SandboxRun:
    try:
        return run_calls(statements, jobs, blocked_paths=material.blocked_paths, **kw)
    except GraderError as exc:  # retried already: the grader's failure, never the student's zero
        if not any(n.startswith(GRADER_ERROR) for n in res.notes):
            res.notes.append(f"{GRADER_ERROR}: {exc}")
        return SandboxRun(checks={j["id"]: CheckRun(failure=GRADER_ERROR) for j in jobs})
    except Exception as exc:  # the sandbox itself failed: say so, grade the others
        res.notes.append(f"the sandbox failed: {exc}")
        return SandboxRun(checks={j["id"]: CheckRun(failure=f"the grader could not run this submission: {exc}")
                                  for j in jobs})


def _judge(run: SandboxRun, plan: dict, judged: dict, honesty: dict, sub: Submission) -> None:
    """Judge every check of ``plan`` (and diagnose from the probes) into ``judged[(function, i)][variant]``."""
    runs = []
    for cid, (fr, i, b, variant) in plan.items():
        cr = run.checks.get(cid, CheckRun(failure="not run"))
        if i == -1:  # the stand-in run of all checks of a function: split it back into checks
            k = 0
            for j, bj in enumerate(b):
                part = cr.calls[k:k + len(bj.calls)]
                k += len(bj.calls)
                runs.append((fr, j, bj, variant, CheckRun(calls=part) if len(part) == len(bj.calls) else
                             CheckRun(failure=cr.failure or "the check did not finish")))
        else:
            runs.append((fr, i, b, variant, cr))
    for fr, i, b, variant, cr in runs:
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
        judged.setdefault((fr.name, i), {})[variant] = (frac, msg)


def _names(names) -> str:
    return " and ".join(names)


def exercise_callees(sub: Submission, func: str, exercise: tuple[str, ...]) -> list[str]:
    """The other exercise functions ``func`` calls (through the submission's own helpers too)
    that have a grader's stand-in (:mod:`.substitutes`)."""
    seen, todo, found = {func}, [func], []
    while todo:
        fn = sub.functions.get(todo.pop())
        for name in sorted(_called_names(fn)) if fn is not None else ():
            if name in exercise and name != func and name in substitutes.SUBSTITUTES:
                if name not in found:
                    found.append(name)
            elif name in sub.functions and name not in seen:
                seen.add(name)
                todo.append(name)
    return found


def _one_charge(results: dict, weight: float, callees: list[str]) -> tuple[float, str]:
    """The score of one check of a function that calls other exercise functions: the better of
    the run with the student's own callees and the run with the grader's stand-ins, in words."""
    own = results.get("own", (0.0, "not run"))
    if not callees or "stand-in" not in results:
        return own
    stand = results["stand-in"]
    who = _names(callees)
    if abs(stand[0] - own[0]) < 1e-12:  # the function-level note says how it was graded
        return stand
    if stand[0] > own[0]:
        return stand[0], "\n".join(x for x in (
            stand[1], f"graded with the grader's {who} in place of yours: with your own {who} this check gets "
            f"{own[0] * weight:.4g} / {weight:g} (the cause is in {who}, charged there)") if x)
    return own[0], "\n".join(x for x in (
        own[1], f"graded with your own {who}: the grader's {who} in its place gives {stand[0] * weight:.4g} / "
        f"{weight:g} here") if x)


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
