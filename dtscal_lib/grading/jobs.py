"""What crosses into the sandbox: one :class:`Job` per check (or diagnosis probe).

The grader's plan (:mod:`.grade`) builds these; :func:`dtscal_lib.grading.sandbox.run_calls`
takes them. Typed fields instead of a dict whose keys each caller spelled out by hand.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Job:
    """One sandboxed run: call ``calls`` (``(function name, args)``) in order, within the limits.

    ``substitute`` holds the sources of the grader's stand-ins for exercise functions that the
    student's function calls (:mod:`.substitutes`), defined after the student's code.
    """

    id: int
    calls: tuple = ()
    wall: float = 10.0
    cpu: int = 10
    substitute: tuple[str, ...] = field(default_factory=tuple)

    def wire(self) -> dict:
        """The job as the sandbox's child process reads it (plain types only, for pickling)."""
        out = {"id": self.id, "calls": list(self.calls), "wall": self.wall, "cpu": self.cpu}
        if self.substitute:
            out["substitute"] = list(self.substitute)
        return out


def as_wire(job) -> dict:
    """A :class:`Job` as a dict; a dict (older callers, tests of the sandbox) as it is."""
    return job.wire() if isinstance(job, Job) else job
