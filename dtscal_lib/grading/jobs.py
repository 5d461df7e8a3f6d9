"""What crosses into the sandbox: one :class:`Job` per check (or diagnosis probe).

The grader's plan (:mod:`.grade`) builds these; :func:`dtscal_lib.grading.sandbox.run_calls`
takes them. Typed fields instead of a dict whose keys each caller spelled out by hand. The
fields, in order, are those of the bubblewrap harness's ``CheckJob`` (issue 22's sandbox), so
either type can stand for the other.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field


@dataclass
class Job:
    """One sandboxed run: call ``calls`` (``[(function name, args)]``) in order, within the limits.

    ``substitute`` holds the sources of the grader's stand-ins for exercise functions that the
    student's function calls (:mod:`.substitutes`), defined after the student's code.
    """

    id: int
    calls: list
    wall: float
    cpu: int
    substitute: list = field(default_factory=list)

    def wire(self) -> dict:
        """The job as plain types (what a sandbox that takes dicts reads; pickles without this module)."""
        out = asdict(self)
        if not self.substitute:
            del out["substitute"]
        return out

    # read like the dict the sandbox took before (``job["id"]``, ``job.get("substitute", ())``)
    def __getitem__(self, key: str):
        return getattr(self, key)

    def get(self, key: str, default=None):
        return getattr(self, key, default)


def as_wire(job) -> dict:
    """A :class:`Job` as a dict; a dict (older callers, tests of the sandbox) as it is."""
    return job.wire() if isinstance(job, Job) else job
