"""Predict, then check: the student commits to an answer in code, runs the experiment, and reads why.

A prediction cell holds a plain assignment the student edits *before* running the experiment::

    my_guess_px = None      # your prediction: by how many pixels do the two pictures differ?

and the experiment cell ends with one of the comparisons below, fed with what the experiment
measured. They are for learning only: no points, never raised (not even under ``DTSCAL_STRICT``),
and the grader never sees them (it grades only functions defined in cells tagged ``exercise``).

* :func:`predict_number` - a number, right when within a tolerance (absolute or relative);
* :func:`predict_choice` - one of a few named answers;
* :func:`predict_points` - a sketch as a few points, right when close to the measured points;
* :func:`check_prediction` - the course's questions: the notebook passes the question's key, the
  prediction and what was measured; the question, its tolerance and its explanation live in
  :mod:`.answers`, never in the notebook, so nothing above the check gives the answer away.

Each returns a :class:`Prediction` whose text (what the notebook shows) states the question, the
prediction, what was measured and why. A missing prediction (``None``) still shows the answer and the
explanation, with a nudge to commit to a guess next time: the explanation is the lesson.

Numbers are shown with a fixed number of decimals (``digits``), so stored notebook outputs are the
same on every machine as long as the measured value is not round-off.

>>> print(predict_number("2 + 2?", 4.2, 4.0, unit="", atol=0.5, why="arithmetic"))
[predict] 2 + 2?
    you predicted 4.20, measured 4.00: right (within 0.50)
    why: arithmetic
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .answers import question

__all__ = ["Prediction", "predict_number", "predict_choice", "predict_points", "check_prediction", "RIGHT", "WRONG",
           "MISSING", "UNREAD"]

RIGHT, WRONG, MISSING = "right", "not quite", "no prediction"
#: a prediction the check could not read (text for a number, a typo in a choice): no answer shown
UNREAD = "not read"


@dataclass(frozen=True)
class Prediction:
    """The outcome of one predict-then-check question (no points: for learning only)."""

    question: str
    verdict: str  #: :data:`RIGHT`, :data:`WRONG` or :data:`MISSING`
    detail: str  #: what was predicted and measured
    why: str  #: the explanation, shown whatever the verdict

    @property
    def right(self) -> bool:
        return self.verdict == RIGHT

    def text(self) -> str:
        lines = [f"[predict] {self.question}", f"    {self.detail}"]
        if self.verdict == MISSING:
            lines.append("    (next time write your prediction in the cell above first: committing to a guess "
                         "is what makes the answer stick)")
        if self.verdict != UNREAD:  # the answer stays hidden until the prediction can be read
            lines.append(f"    why: {self.why}")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.text()

    def __repr__(self) -> str:  # what a notebook cell shows
        return self.text()


def _fmt(x: float, digits: int) -> str:
    s = f"{float(x):.{digits}f}"
    return s[1:] if s.startswith("-") and float(s) == 0 else s  # never "-0.00"


def _number(value, what: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be a number, got {value!r}; write e.g. 3.5") from None
    if not math.isfinite(x):
        raise ValueError(f"{what} must be a finite number, got {value!r}")
    return x


def predict_number(question: str, prediction, measured, *, unit: str = "", atol: float = 0.0, rtol: float = 0.0,
                   digits: int = 2, why: str) -> Prediction:
    """Compare a predicted number with the measured one: right when ``|p - m| <= atol + rtol |m|``.

    Raises
    ------
    ValueError
        When neither tolerance is positive, or the prediction is not a number (with what to write).
    """
    if atol <= 0 and rtol <= 0:
        raise ValueError("give a tolerance: atol > 0 or rtol > 0 (a prediction is never exact)")
    m = _number(measured, "the measured value")
    u = f" {unit}" if unit else ""
    tol = atol + rtol * abs(m)
    if prediction is None:
        return Prediction(question, MISSING, f"measured {_fmt(m, digits)}{u}", why)
    p = _number(prediction, "your prediction")
    ok = abs(p - m) <= tol
    verdict = RIGHT if ok else WRONG
    how = f"within {_fmt(tol, digits)}{u}" if ok else f"off by {_fmt(abs(p - m), digits)}{u}"
    return Prediction(question, verdict, f"you predicted {_fmt(p, digits)}{u}, measured {_fmt(m, digits)}{u}: "
                                         f"{verdict} ({how})", why)


def predict_choice(question: str, prediction, answer: str, choices: Sequence[str], *, why: str) -> Prediction:
    """Compare a chosen answer (one of ``choices``, case and surrounding spaces ignored) with the right one.

    Raises
    ------
    ValueError
        When ``answer`` is not among ``choices``, or the prediction is not one of them (listing them).
    """
    options = [str(c) for c in choices]
    norm = {c.strip().lower(): c for c in options}
    if answer.strip().lower() not in norm:
        raise ValueError(f"the answer {answer!r} is not among the choices {options}")
    answer = norm[answer.strip().lower()]
    if prediction is None:
        return Prediction(question, MISSING, f"the answer is {answer!r}", why)
    key = str(prediction).strip().lower()
    if key not in norm:
        raise ValueError(f"your prediction {prediction!r} is not one of the choices: "
                         + ", ".join(repr(c) for c in options))
    ok = norm[key] == answer
    verdict = RIGHT if ok else WRONG
    return Prediction(question, verdict, f"you chose {norm[key]!r}, the answer is {answer!r}: {verdict}", why)


def predict_points(question: str, prediction, measured, *, tol: float, unit: str = "", digits: int = 1,
                   why: str) -> Prediction:
    """Compare a sketch (N, 2 points, in the measured points' order) with the measured points.

    Right when the RMS distance between corresponding points is at most ``tol``.

    Raises
    ------
    ValueError
        When ``tol`` is not positive or the sketch does not have the measured points' shape.
    """
    if tol <= 0:
        raise ValueError("give a positive tolerance tol")
    m = np.asarray(measured, dtype=float).reshape(-1, 2)
    u = f" {unit}" if unit else ""
    shown = "; ".join(f"({_fmt(a, digits)}, {_fmt(b, digits)})" for a, b in m)
    if prediction is None:
        return Prediction(question, MISSING, f"measured points: {shown}{u}", why)
    try:
        p = np.asarray(prediction, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"your sketch must be {len(m)} points (x, y), e.g. [(0, 0), (1, 2)]") from None
    if p.size != m.size:
        raise ValueError(f"your sketch has {p.size // 2 if p.size % 2 == 0 else p.size / 2} points; "
                         f"give {len(m)} points (x, y), one per measured point, in the same order")
    rms = float(np.sqrt(np.mean(np.sum((p.reshape(-1, 2) - m) ** 2, axis=1))))
    ok = rms <= tol
    verdict = RIGHT if ok else WRONG
    return Prediction(question, verdict, f"your sketch is {_fmt(rms, digits)}{u} RMS from the measured points "
                                         f"{shown}{u}: {verdict} (tolerance {_fmt(tol, digits)}{u})", why)


def check_prediction(key: str, prediction, measured, **facts) -> Prediction:
    """Judge the course's prediction ``key`` (see :mod:`.answers`) against what the experiment measured.

    ``measured`` is a number, or for a choice question the right choice; ``facts`` are the experiment's
    other numbers the explanation quotes. A prediction the check cannot read (text where a number is
    asked, an answer not among the choices) is never an error: the result names the variable to fix
    and what to write, and keeps the answer hidden.

    >>> print(check_prediction("01.width_ratio", "1.6x", 1.61))  # doctest: +ELLIPSIS
    [predict] how many times wider does the board look at 0.28 m than at 0.45 m?
        could not read your prediction: predict_width_ratio = '1.6x' is not a number; write a number ...
    """
    q = question(key)
    if q.is_choice:
        key_p = None if prediction is None else str(prediction).strip().lower()
        if key_p is not None and key_p not in {c.lower() for c in q.choices}:
            return Prediction(q.text, UNREAD, f"could not read your prediction: {q.var} = {prediction!r} is not one "
                                              "of " + ", ".join(repr(c) for c in q.choices)
                              + f"; write e.g. {q.var} = {q.choices[0]!r} (with the quotes) and run this cell again",
                              "")
        res = predict_choice(q.text, prediction, measured, q.choices, why="")
        return Prediction(q.text, res.verdict, res.detail, q.why(measured, prediction, facts))
    if prediction is not None:
        try:
            p = float(prediction)
            ok = math.isfinite(p)
        except (TypeError, ValueError):
            ok = False
        if not ok:
            return Prediction(q.text, UNREAD, f"could not read your prediction: {q.var} = {prediction!r} is not a "
                                              f"number; write a number without quotes or unit, e.g. {q.var} = 2.5, "
                                              "and run this cell again", "")
    res = predict_number(q.text, prediction, measured, unit=q.unit, atol=q.atol, rtol=q.rtol, digits=q.digits, why="")
    return Prediction(q.text, res.verdict, res.detail, q.why(float(measured), prediction, facts))
