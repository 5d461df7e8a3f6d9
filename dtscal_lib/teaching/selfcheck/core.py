"""The self-checks' machinery: cases, reports, comparisons (re-exported by :mod:`dtscal_lib.teaching.selfcheck`).

The check modules (``projection``, ``homography``, ...) import it from here, so no module of the package
imports the package itself.
"""

from __future__ import annotations

import traceback
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ...exercise_rules import RETURNS, live_charges, return_type_problem
from ...mistakes import FUNCTIONS, diagnose_function, precision_problem, probe_args

PASS, FAIL, NOT_IMPLEMENTED = "pass", "fail", "not implemented yet"


class CheckFailed(AssertionError):
    """Raised by a case to fail it with a message for the student.

    ``hint`` names what to do about THIS failure (a wrong shape, a flipped sign) and replaces the case's
    general hint, which is about the case's values: a student sees only the hint about the mistake made.
    """

    def __init__(self, message: str = "", *, hint: str | None = None):
        super().__init__(message)
        self.hint = hint


@dataclass
class Case:
    """One test case: ``run(fn)`` raises :class:`CheckFailed` (or any error) to fail."""

    title: str
    run: Callable[[Callable], Any]
    hint: str = ""


@dataclass
class CaseResult:
    title: str
    status: str
    message: str = ""
    hint: str = ""


@dataclass
class Report:
    """What a check found. ``status`` is ``"pass"``, ``"fail"`` or ``"not implemented yet"``."""

    name: str
    results: list[CaseResult] = field(default_factory=list)
    #: the recognised mistake (one line, see :mod:`.diagnosis`), shown before the cases
    diagnosis: str = ""

    @property
    def status(self) -> str:
        if any(r.status == NOT_IMPLEMENTED for r in self.results):
            return NOT_IMPLEMENTED
        return PASS if self.results and all(r.status == PASS for r in self.results) else FAIL

    @property
    def passed(self) -> bool:
        return self.status == PASS

    def text(self) -> str:
        if self.status == NOT_IMPLEMENTED:
            return f"[ ] {self.name}: not implemented yet (replace the `raise NotImplementedError` with your code)"
        n_ok = sum(r.status == PASS for r in self.results)
        head = f"[{'x' if self.passed else '!'}] {self.name}: {n_ok}/{len(self.results)} checks passed"
        lines = [head] + ([f"    {self.diagnosis}"] if self.diagnosis else [])
        for r in self.results:
            mark = "ok  " if r.status == PASS else "FAIL"
            lines.append(f"    {mark} {r.title}" + (f": {r.message}" if r.message and r.status != PASS else ""))
            if r.status != PASS and r.hint and not self.diagnosis:  # the diagnosis replaces generic hints
                lines.append(f"         hint: {r.hint}")
        return "\n".join(lines)

    def __repr__(self) -> str:  # what a notebook cell shows
        return self.text()


def run_check(name: str, fn: Callable, cases: list[Case], *, show: bool = True, graded: bool = True) -> Report:
    """Run ``cases`` against the student's ``fn``; print and return the :class:`Report`.

    ``graded=False`` is for the student's own practice functions: their check never raises, not even under
    ``DTSCAL_STRICT`` (nbval as an autograder grades the exercises only).

    A case that raises ``NotImplementedError`` stops the check (the function is still the
    stub). Any other exception fails that case with the exception's message, so student
    errors never escape the check and the notebook runs on.
    """
    report = Report(name)
    refused = _refused(name, fn)
    if refused:  # the grader gives no credit for this function: the same words, no case run
        report.results = [CaseResult(RULES_TITLE, FAIL, refused)]
        cases = []
    for case in cases:
        try:
            case.run(fn)
        except NotImplementedError:
            report.results = [CaseResult(case.title, NOT_IMPLEMENTED)]
            break
        except CheckFailed as exc:
            report.results.append(CaseResult(case.title, FAIL, str(exc), case.hint if exc.hint is None else exc.hint))
        except Exception as exc:  # student code may raise anything
            tb = traceback.extract_tb(exc.__traceback__)
            where = f" (line {tb[-1].lineno} in {tb[-1].name})" if tb else ""
            report.results.append(CaseResult(case.title, FAIL, f"{type(exc).__name__}: {exc}{where}", case.hint))
        else:
            report.results.append(CaseResult(case.title, PASS))
    if report.status == PASS and name in RETURNS:  # the rule table's contract, on the catalogue's probes
        report.results += _contract(name, fn)
    if report.status == FAIL and not refused:
        if name in FUNCTIONS:
            mistake = diagnose_function(name, fn)
            report.diagnosis = mistake.line() if mistake else ""
    if show:
        print(report.text())
    if graded and strict() and not report.passed:
        raise SelfCheckFailed(report.text())
    return report


#: the title of the case that states a broken rule of the notebook's rule table
RULES_TITLE = "the rules of this notebook's exercises (imports, academic honesty)"


def _refused(name: str, fn: Callable) -> str:
    """Why the grader refuses ``fn`` outright (a solving routine, a module the notebook does not allow), in the
    grader's words, or ""."""
    if name not in RETURNS:
        return ""
    honesty, modules = live_charges(name, fn)
    return honesty or modules


def _contract(name: str, fn: Callable) -> list[CaseResult]:
    """The return type and the precision contract on the mistake catalogue's probes, judged by the functions the
    grader uses; a failing rule is listed, a kept one adds nothing to the report."""
    args_list, outputs = probe_args(name), []
    for args in args_list:
        try:
            outputs.append(fn(*args))
        except Exception as exc:  # noqa: BLE001 - student code may raise anything
            return [CaseResult("the public probes of the rule table", FAIL, f"{type(exc).__name__}: {exc}")]
    out = []
    why = return_type_problem(name, outputs[0])
    if why:
        out.append(CaseResult("returns numpy arrays (the notebook's return types)", FAIL, why))
    why = precision_problem(name, args_list, outputs)
    if why:
        out.append(CaseResult("computed in float64 (the precision contract)", FAIL, why))
    return out


class SelfCheckFailed(AssertionError):
    """Raised by a self-check that does not pass when ``DTSCAL_STRICT`` is set (nbval grading)."""


def strict() -> bool:
    """True when the environment asks self-checks to raise (``DTSCAL_STRICT=1``, for ``pytest --nbval-lax``).

    In JupyterLab the variable is unset, so a failing check prints and the notebook runs on.
    """
    import os

    return os.environ.get("DTSCAL_STRICT", "").strip().lower() not in ("", "0", "false", "no")


def num(x) -> str:
    """A number as plain text: ``659.4``, never ``np.float64(659.4)``.

    >>> num(np.float64(659.4))
    '659.4'
    """
    return f"{float(x):.6g}"


def nums(values, digits: int = 4) -> str:
    """A short vector as plain text: ``(0.117, 0.004)``.

    >>> nums(np.array([0.11712, 0.0041]))
    '(0.1171, 0.0041)'
    """
    return "(" + ", ".join(f"{round(float(v), digits):g}" for v in np.ravel(values)) + ")"


def expect_shape(value, shape: tuple, what: str) -> np.ndarray:
    """Fail unless ``value`` converts to a float array of ``shape`` (None matches any size)."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except Exception:
        raise CheckFailed(f"{what} should be a numeric array, got {type(value).__name__}") from None
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise CheckFailed(f"{what} should have shape {want}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise CheckFailed(f"{what} contains NaN or infinite values")
    return arr


def expect_close(value, expected, atol: float, what: str, rtol: float = 0.0) -> None:
    """Fail unless ``value`` is within ``atol + rtol*|expected|`` of ``expected`` everywhere."""
    v = np.asarray(value, dtype=np.float64)
    e = np.asarray(expected, dtype=np.float64)
    if v.shape != e.shape:
        raise CheckFailed(f"{what} should have shape {e.shape}, got {v.shape}")
    err = np.abs(v - e)
    tol = atol + rtol * np.abs(e)
    if not np.all(err <= tol):
        i = np.unravel_index(np.nanargmax(err - tol), err.shape) if err.ndim else ()
        raise CheckFailed(
            f"{what} is off by up to {np.nanmax(err):.3g} (allowed {atol:g}"
            + (f" + {rtol:g} relative" if rtol else "") + f"); worst at index {tuple(int(x) for x in i)}: "
            f"got {num(v[i])}, expected {num(e[i])}"
        )
