"""Failures of the grader itself, never of the student's code.

A :class:`GraderError` (the sandbox could not start, the machine ran out of memory or
processes on the grader's side) is retried by :mod:`.grade`; if it persists, the function is
reported as "not graded: grader error, rerun" — a status of its own in the CSV, the JSON and
the class report, never the student's 0 (issue 22: under load a correct submission was given
0 with "the grading process failed to start").
"""

from __future__ import annotations


class GraderError(Exception):
    """The grader (not the submission) failed: raised by the sandbox when it cannot start."""


#: what every report says for a function the grader could not run
GRADER_ERROR = "not graded: grader error, rerun"
