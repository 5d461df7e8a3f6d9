"""Grade one submission (a notebook or a .py file) of one assignment.

:func:`grade_file` runs the named steps of :data:`STEPS` in order over one :class:`Grading`
(the typed state of one submission), as nbgrader runs its list of preprocessors:

1. ``read``: parse the submission (:mod:`.loader`, nothing runs);
2. ``screen``: functions missing, still stubs, or calling a solving routine get 0 with the reason;
3. ``run_own``: the other functions' checks and diagnosis probes run in the sandbox
   (:mod:`.sandbox`, one :class:`~.jobs.Job` per check), and are judged against the references
   computed here (:mod:`.checks`); the mistake is named (:mod:`dtscal_lib.mistakes`, the catalogue both wings import);
4. ``run_stand_ins``: one bug, one charge — a function whose callee lost points runs again with the
   grader's stand-in for that callee;
5. ``score``: the better of the two runs per check; checks of form count only once a value is right;
6. ``explain``: notes on callees, honesty caught at run time, "not implemented".

A failure of the grader itself (the sandbox does not start: :class:`~.errors.GraderError` or any
exception of :func:`~.sandbox.run_calls`) is retried :data:`GRADER_ATTEMPTS` times, then the
functions concerned read "not graded: grader error, rerun" (status :data:`GRADER_ERROR_STATUS`),
never the student's 0.
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, NamedTuple

from .. import mistakes as diagnosis
from ..exercise_rules import charges, honesty_reason, module_reason
from . import substitutes
from .checks import Built
from .errors import GRADER_ERROR
from .jobs import Job
from .loader import Submission, _called_names, load_submission, useful_import
from .material import ASSIGNMENTS, Material
from .sandbox import CPU_S, WALL_S, CheckRun, SandboxRun, run_calls, validate_limits

NOT_IMPLEMENTED = "not implemented (the function still raises NotImplementedError)"
#: a function using a module its notebook's rule table does not allow (:mod:`dtscal_lib.exercise_rules`)
NOT_ALLOWED_STATUS = "not allowed"
#: a function the grader could not run: its own status, not a score of the student's
GRADER_ERROR_STATUS = "grader error"
#: tries of a sandbox run that fails on the grader's side, and the pause before the second and third
GRADER_ATTEMPTS = 3
GRADER_RETRY_PAUSE_S = (1.0, 3.0)
FORM_GATED = ("no points for form yet: none of this function's answers is right on any case, and checks of form "
              "(dtype, shape, inputs untouched, raising, H[2, 2] = 1, precision) count only once the values are "
              "right on at least one case")


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
    #: why the grader (not the student) failed on part of this submission; "" when it did not
    grader_error: str = ""

    @property
    def score(self) -> float:
        return round(sum(f.score for f in self.functions), 2)

    @property
    def max_score(self) -> float:
        return round(sum(f.max_score for f in self.functions), 2)


# --------------------------------------------------------------------------- the typed plan
@dataclass(frozen=True)
class Limits:
    """Per check: wall-clock and CPU seconds; per submission: memory (MB, None = the sandbox's default)."""

    wall_s: float = WALL_S
    cpu_s: int = CPU_S
    mem_mb: int | None = None


class Verdict(NamedTuple):
    """A check judged on one run: the fraction of its points in [0, 1], and what the student reads."""

    fraction: float
    message: str


@dataclass
class OwnPoints:
    """A function's points with the student's own callees (said when the stand-in run counted instead)."""

    value: float = 0.0
    form: float = 0.0
    #: a check of value is right on at least one case (form counts only then)
    right: bool = False


@dataclass(frozen=True)
class Part:
    """A check judged from a job's answers: its index among the function's checks, and the check."""

    index: int
    check: Built


@dataclass(frozen=True)
class Planned:
    """One sandbox job and what its answers are for.

    ``parts`` are the checks whose calls the job makes, laid end to end (one check for a run with
    the student's own callees; every check of the function for the stand-in run); ``probe`` is set
    instead for the diagnosis probe (its answers name the mistake, they score nothing)."""

    job: Job
    function: FunctionResult
    variant: str  # "own": the student's code as it is; "stand-in": the grader's callees in its place
    parts: tuple[Part, ...] = ()
    probe: tuple | None = None


@dataclass
class Grading:
    """The state of one submission as the steps fill it in."""

    path: Path
    material: Material
    assignment: str
    limits: Limits
    res: GradeResult
    sub: Submission | None = None
    checks: dict[str, list[Built]] = field(default_factory=dict)
    statements: list[tuple[str, int]] = field(default_factory=list)
    #: per function, the other exercise functions it calls that have a grader's stand-in
    stand_ins: dict[str, list[str]] = field(default_factory=dict)
    #: the functions run again with stand-ins, and for which callees
    again: dict[str, list[str]] = field(default_factory=dict)
    #: (function, check index) -> {variant: verdict}
    judged: dict[tuple[str, int], dict[str, Verdict]] = field(default_factory=dict)
    #: (function, variant) -> solving routines its calls reached inside the sandbox
    honesty: dict[tuple[str, str], set] = field(default_factory=dict)
    #: function -> its points with the student's own callees
    own_points: dict[str, OwnPoints] = field(default_factory=dict)

    def function(self, name: str) -> FunctionResult:
        return next(f for f in self.res.functions if f.name == name)

    def graded(self) -> list[FunctionResult]:
        return [f for f in self.res.functions if f.status == "graded"]


# --------------------------------------------------------------------------- the steps
def read(g: Grading) -> None:
    """Parse the submission; an unreadable file grades as an empty one, with the reason."""
    try:
        g.sub = load_submission(g.path)
    except Exception as exc:  # unreadable file: zero, with the reason
        g.sub = Submission(g.path)
        g.res.notes.append(f"the submission could not be read: {exc}")
    g.res.notes += [f"syntax error, cell skipped: {e}" for e in g.sub.syntax_errors]
    g.checks = g.material.checks(g.assignment)
    statements = [(useful_import(src), line) if src.lstrip().startswith(("import ", "from ")) else (src, line)
                  for src, line in g.sub.statements]
    g.statements = [st for st in statements if st[0] is not None]


def screen(g: Grading) -> None:
    """A function missing, still a stub or calling a solving routine: 0 on every check, with the reason."""
    sub = g.sub
    # one call, one charge: a routine reached through another exercise function is charged to that function
    found = charges(sub.functions, sub.aliases, g.assignment, ASSIGNMENTS[g.assignment])
    for func in ASSIGNMENTS[g.assignment]:
        fr = FunctionResult(func)
        g.res.functions.append(fr)
        reason = ""
        if func not in sub.functions:
            reason = f"{func} is not defined in the submission"
            fr.status = "missing"
        elif func in sub.stubs:
            reason, fr.status = NOT_IMPLEMENTED, "not implemented"
        elif func in found.honesty:
            fr.status = "academic honesty"
            reason = honesty_reason(func, found.honesty[func])
        elif func in found.modules:
            fr.status = NOT_ALLOWED_STATUS
            reason = module_reason(func, found.modules[func], g.assignment)
        fr.tests = [TestResult(b.name, func, 0.0, b.weight, reason) for b in g.checks[func]]
        if not reason:
            callees = exercise_callees(sub, func, ASSIGNMENTS[g.assignment])
            if callees:
                g.stand_ins[func] = callees


def run_own(g: Grading) -> None:
    """Every check of every function still graded, and its diagnosis probe, with the student's own code."""
    plan: list[Planned] = []
    for fr in g.graded():
        for i, b in enumerate(g.checks[fr.name]):
            plan.append(Planned(Job(len(plan), list(b.calls), g.limits.wall_s, g.limits.cpu_s), fr, "own",
                                (Part(i, b),)))
        probe = tuple(diagnosis.probe_args(fr.name))
        plan.append(Planned(Job(len(plan), [(fr.name, a) for a in probe], g.limits.wall_s, g.limits.cpu_s),
                            fr, "own", probe=probe))
    _run_and_judge(g, plan)


def run_stand_ins(g: Grading) -> None:
    """One bug, one charge: a function whose callee lost points runs again with the grader's stand-in
    for the callee (a second, smaller sandbox run, only for those functions); ``score`` keeps the better."""
    lost = {fr.name for fr in g.res.functions if fr.status != "graded" or fr.diagnosis or any(
        g.judged.get((fr.name, i), {}).get("own", Verdict(0.0, "")).fraction < 1
        for i in range(len(g.checks[fr.name])))}
    g.again = {f: cs for f, cs in g.stand_ins.items() if set(cs) & lost and g.function(f).status == "graded"}
    plan: list[Planned] = []
    for fr in g.graded():
        if fr.name not in g.again:
            continue
        subst = tuple(substitutes.source(c) for c in g.again[fr.name])
        checks = g.checks[fr.name]
        n = len(checks)
        plan.append(Planned(Job(len(plan), [c for b in checks for c in b.calls], g.limits.wall_s * n,
                                g.limits.cpu_s * n, list(subst)), fr, "stand-in",
                            tuple(Part(i, b) for i, b in enumerate(checks))))
        probe = tuple(diagnosis.probe_args(fr.name))
        plan.append(Planned(Job(len(plan), [(fr.name, a) for a in probe], g.limits.wall_s, g.limits.cpu_s,
                                list(subst)), fr, "stand-in", probe=probe))
        fr.diagnosis, fr.mistake = "", None  # the diagnosis of this function alone, with the stand-in
    _run_and_judge(g, plan)


def score(g: Grading) -> None:
    """Per check, the better of the two runs (one bug, one charge); form counts once a value is right."""
    value_right: dict[str, bool] = {}
    for fr in g.graded():
        for i, b in enumerate(g.checks[fr.name]):
            if (fr.name, i) not in g.judged:
                continue
            frac, msg = _one_charge(g.judged[(fr.name, i)], b.weight, g.again.get(fr.name, []))
            own = g.judged[(fr.name, i)].get("own", Verdict(0.0, "")).fraction
            pts = g.own_points.setdefault(fr.name, OwnPoints())
            if b.form:
                pts.form += own * b.weight
            else:
                pts.value += own * b.weight
                pts.right |= own > 0
            fr.tests[i] = TestResult(b.name, fr.name, round(frac * b.weight, 4), b.weight, msg)
            value_right[fr.name] = value_right.get(fr.name, False) or (not b.form and frac > 0)
    for fr in g.graded():  # form gives points only to a function that computes something right
        if not value_right.get(fr.name, False):
            for i, b in enumerate(g.checks[fr.name]):
                if b.form and fr.tests[i].score > 0:
                    fr.tests[i] = TestResult(b.name, fr.name, 0.0, b.weight, FORM_GATED)


def explain(g: Grading) -> None:
    """Say how callees were treated; honesty caught at run time; a function that only raised is not implemented."""
    for fr in g.graded():  # one bug, one charge: say how the callee was treated
        if fr.name not in g.stand_ins:
            continue
        who = _names(g.stand_ins[fr.name])
        if fr.name not in g.again:
            g.res.notes.append(f"{fr.name} calls {who}, which passes all its checks: graded with yours.")
            continue
        pts = g.own_points.get(fr.name, OwnPoints())
        own = pts.value + (pts.form if pts.right else 0.0)
        changed = f"With your own {who}, {fr.name} would score {own:.4g} / {fr.max_score:g} instead of " \
                  f"{fr.score:g}." if abs(own - fr.score) > 1e-9 else f"Your own {who} gives it the same score."
        g.res.notes.append(f"{fr.name} calls {who}, which lost points: graded with the grader's {who} in place of "
                           f"yours and with yours, the better counts, so a mistake in {who} is charged there "
                           f"only. {changed}")
    for fr in g.res.functions:
        if fr.status == GRADER_ERROR_STATUS:
            continue
        # caught at run time: a route the syntax check missed. A function run again with the grader's stand-ins
        # is judged on that run only: with its own callees, the call may be the callee's (charged there)
        used = g.honesty.get((fr.name, "stand-in" if fr.name in g.again else "own"))
        if used:
            names = ", ".join(sorted(used))
            fr.status = "academic honesty"
            why = (f"no credit: while it ran, {fr.name} called {names}, which does the exercise for you "
                   "(caught inside the sandbox). Write the computation yourself.")
            fr.tests = [TestResult(t.name, t.function, 0.0, t.max_score, why) for t in fr.tests]
            continue
        if fr.status == "graded" and all(t.output.startswith("not implemented") for t in fr.tests):
            fr.status = "not implemented"


#: the steps of :func:`grade_file`, in order
STEPS: tuple[Callable[[Grading], None], ...] = (read, screen, run_own, run_stand_ins, score, explain)


def grade_file(path, material: Material, assignment: str, *, student: str = "",
               wall_s: float = WALL_S, cpu_s: int = CPU_S, mem_mb: int | None = None) -> GradeResult:
    """Grade one notebook or .py file against ``assignment``; never raises on student code."""
    validate_limits(wall_s, cpu_s, mem_mb)
    t0 = time.perf_counter()
    path = Path(path)
    g = Grading(path, material, assignment, Limits(wall_s, cpu_s, mem_mb),
                GradeResult(str(path), assignment, student or path.stem))
    for step in STEPS:
        step(g)
    g.res.execution_time = time.perf_counter() - t0
    return g.res


# --------------------------------------------------------------------------- running and judging
def _run_and_judge(g: Grading, plan: list[Planned]) -> None:
    if not plan:
        return
    by_id = {p.job.id: p for p in plan}
    run, lost = _sandbox(g, [p.job for p in plan], lambda cid, cr: _judge(g, by_id[cid], cr))
    # the grader failed, not the student: a function with a check that was never answered is not
    # graded yet (its answered checks wait for the rerun too); a lost probe only costs the diagnosis
    failed = {id(p.function): p.function for p in plan if p.job.id in lost and p.probe is None}
    for fr in failed.values():
        fr.status, fr.diagnosis, fr.mistake = GRADER_ERROR_STATUS, "", None
        fr.tests = [TestResult(t.name, t.function, 0.0, t.max_score, f"{GRADER_ERROR} ({g.res.grader_error})")
                    for t in fr.tests]
    for k, err in run.load_errors:
        where = g.sub.where(g.statements[k][1]) if k < len(g.statements) else "?"
        note = f"statement at {where} skipped: {_cell_lines(g.sub, err)}"
        if note not in g.res.notes:
            g.res.notes.append(note)


def _sandbox(g: Grading, jobs: list[Job], judge) -> tuple[SandboxRun, set[int]]:
    """The sandbox run of ``jobs`` and the ids of those never answered: a failure of the grader's
    side is retried (the unanswered jobs only, keeping the answers already given); what is still
    unanswered after :data:`GRADER_ATTEMPTS` tries is the grader's failure, never a 0. Each answer
    is judged as it arrives (``judge``) and then dropped."""
    kw = {"mem_mb": g.limits.mem_mb} if g.limits.mem_mb else {}
    merged, errors, todo = SandboxRun(), [], list(jobs)
    for attempt in range(GRADER_ATTEMPTS):
        if attempt:
            time.sleep(GRADER_RETRY_PAUSE_S[min(attempt, len(GRADER_RETRY_PAUSE_S)) - 1])
        try:
            run = run_calls(g.statements, todo, judge=judge, **kw)
        except Exception as exc:  # noqa: BLE001 - the sandbox itself failed (GraderError or worse): try again
            errors.append(f"{type(exc).__name__}: {str(exc).strip()[:300]}")
            run = getattr(exc, "run", None)  # what it answered before it failed
        if run is not None:
            merged.checks.update(run.checks)
            merged.notes.update(run.notes)
            merged.load_errors += [e for e in run.load_errors if e not in merged.load_errors]
        todo = [j for j in jobs if j.id not in merged.checks]
        if not todo:
            return merged, set()
    g.res.grader_error = f"the sandbox failed {len(errors)} times; last: {errors[-1]}"
    g.res.notes.append(f"{GRADER_ERROR}: {g.res.grader_error}")
    return merged, {j.id for j in todo}


def _judge(g: Grading, p: Planned, cr: CheckRun) -> None:
    """Judge the checks of one job ``p`` from its run ``cr`` (or diagnose from the probe) into
    ``g.judged[(function, i)][variant]``."""
    fr = p.function
    if p.probe is not None:
        try:
            _diagnose(fr, list(p.probe), cr)
        except Exception:  # noqa: BLE001 - no diagnosis is better than no grade
            fr.diagnosis = ""
        return
    k = 0
    for part in p.parts:  # the calls of each check, laid end to end in the job
        b = part.check
        one = cr
        if len(p.parts) > 1 or p.variant == "stand-in":
            calls = cr.calls[k:k + len(b.calls)]
            k += len(b.calls)
            one = CheckRun(calls=calls) if len(calls) == len(b.calls) else \
                CheckRun(failure=cr.failure or "the check did not finish")
        used = sorted({h for c in one.calls for h in c.honesty})
        if used:
            g.honesty.setdefault((fr.name, p.variant), set()).update(used)
        frac, msg = b.judge(b, one)
        msg = _cell_lines(g.sub, msg)
        frac = min(1.0, max(0.0, float(frac)))
        printed = next((c.stdout for c in one.calls if c.stdout.strip()), "")
        if printed and frac < 1:
            msg += f"\nprinted: {printed[:300]}" + (" ... (output truncated)" if len(printed) > 300 else "")
        g.judged.setdefault((fr.name, part.index), {})[p.variant] = Verdict(frac, msg)


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


def _one_charge(results: dict[str, Verdict], weight: float, callees: list[str]) -> Verdict:
    """The score of one check of a function that calls other exercise functions: the better of
    the run with the student's own callees and the run with the grader's stand-ins, in words."""
    own = results.get("own", Verdict(0.0, "not run"))
    if not callees or "stand-in" not in results:
        return own
    stand = results["stand-in"]
    who = _names(callees)
    if abs(stand.fraction - own.fraction) < 1e-12:  # the function-level note says how it was graded
        return stand
    if stand.fraction > own.fraction:
        return Verdict(stand.fraction, "\n".join(x for x in (
            stand.message, f"graded with the grader's {who} in place of yours: with your own {who} this check gets "
            f"{own.fraction * weight:.4g} / {weight:g} (the cause is in {who}, charged there)") if x))
    return Verdict(own.fraction, "\n".join(x for x in (
        own.message, f"graded with your own {who}: the grader's {who} in its place gives "
        f"{stand.fraction * weight:.4g} / {weight:g} here") if x))


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


#: the diagnosis compares a probe's answers with each named mistake, making arrays of their size:
#: answers larger than this (the largest probe answer, notebook 04's 640x480 pair of maps, has
#: 614,400 numbers) match no mistake, and are not compared (the grader's memory stays its own)
MAX_PROBE_NUMBERS = 2_000_000


def _diagnose(fr: FunctionResult, probe: list, cr: CheckRun) -> None:
    if cr.failure or len(cr.calls) < len(probe):
        return
    if any(getattr(c.value, "size", 0) > MAX_PROBE_NUMBERS for c in cr.calls):
        return
    outputs = [c.value if c.ok else RuntimeError(c.error) for c in cr.calls]
    mistake = diagnosis.diagnose(fr.name, probe, outputs)
    if mistake is not None:
        fr.diagnosis = mistake.line()
        fr.mistake = (str(getattr(mistake, "key", fr.diagnosis)), str(getattr(mistake, "text", fr.diagnosis)),
                      str(getattr(mistake, "equation", "")))
