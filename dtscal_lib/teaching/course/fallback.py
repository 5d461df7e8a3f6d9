"""The course's one fallback contract: the student's function, or the kit's stand-in.

A notebook wraps each exercise function it uses later once::

    project = course.use_or_fallback(project_points, stand_in, check=check_project_points,
                                     fallback_name="the kit's camera.project_points")

When the function's self-check passes (run silently), ``project`` is the student's function
and one line says so. Otherwise ``project`` is the stand-in and a framed banner says what
is used instead and why, once, so every later cell still runs. A student function that
passes its check but raises on the notebook's data falls back for that call, with one banner.
Every notebook uses this contract and no other.
"""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from ...errors import DtscalError

__all__ = ["Fallback", "use_or_fallback", "banner", "notebook_function"]


def banner(what: str, then: str) -> None:
    """Print a framed two-line message that stands out in a notebook's output."""
    line = "!" * 78
    print(f"{line}\n!! {what}\n!! -> {then}\n{line}")


def _unavailable(*args, **kwargs):
    raise NotImplementedError("the student's function could not be loaded")


@dataclass
class Fallback:
    """A callable that runs the student's function, or the stand-in while it does not work.

    Made by :func:`use_or_fallback`; ``uses_student`` says which one runs and ``label``
    names it for figure legends and messages.
    """

    name: str
    student: Callable
    fallback: Callable
    fallback_name: str
    uses_student: bool
    reason: str = ""
    #: True when the last call ran the stand-in (always, or because the student's function raised)
    last_fell_back: bool = False
    _warned: list = field(default_factory=list, repr=False)

    @property
    def chosen(self) -> Callable:
        """The function in use, without the per-call fallback (its errors propagate)."""
        return self.student if self.uses_student else self.fallback

    @property
    def label(self) -> str:
        """What runs, for legends and tables: ``"your name"`` or the stand-in's name."""
        return f"your {self.name}" if self.uses_student else self.fallback_name

    def __call__(self, *args, **kwargs):
        self.last_fell_back = not self.uses_student
        if self.uses_student:
            try:
                return self.student(*args, **kwargs)
            except Exception as exc:  # the student's code failed on the notebook's data
                self.last_fell_back = True
                if not self._warned:
                    self._warned.append(True)
                    banner(f"your `{self.name}` raised {type(exc).__name__}: {exc}",
                           f"using {self.fallback_name} for this call (and any later failing call) instead")
                return self.fallback(*args, **kwargs)
        return self.fallback(*args, **kwargs)


def use_or_fallback(student: Callable | None, fallback: Callable, *, check: Callable | None = None,
                    name: str | None = None, fallback_name: str = "the kit's stand-in") -> Fallback:
    """Decide once whether the notebook uses the student's function or a stand-in.

    Parameters
    ----------
    student : the student's function (None when it could not be loaded)
    fallback : same signature; OpenCV or the kit's own implementation
    check : the function's self-check (``check(fn).status == "pass"`` means it works);
        without one, the student's function is used and a call that raises falls back
    name : the function's name in messages (default ``student.__name__``)
    fallback_name : what the stand-in is, for messages and legends

    Returns
    -------
    Fallback, a callable with the student's signature

    Examples
    --------
    >>> def stub(x):
    ...     raise NotImplementedError("not written")
    >>> f = use_or_fallback(stub, abs, fallback_name="abs")
    using your `stub`
    >>> f(-2)                                                  # doctest: +ELLIPSIS
    !!!...
    !! your `stub` raised NotImplementedError: not written
    !! -> using abs for this call (and any later failing call) instead
    !!!...
    2
    """
    name = name or getattr(student, "__name__", "your function")
    if student is None:
        banner(f"your `{name}` is not available",
               f"using {fallback_name} until your function works (the cells below still run)")
        return Fallback(name, _unavailable, fallback, fallback_name, False, "is not available")
    if check is not None:
        with contextlib.redirect_stdout(io.StringIO()):
            status = check(student).status
        ok = status == "pass"
        reason = "is not implemented yet" if status == "not implemented yet" else "does not pass its self-check yet"
    else:
        ok, reason = True, ""
    if ok:
        print(f"using your `{name}`")
    else:
        banner(f"`{name}` {reason}", f"using {fallback_name} until your function works (the cells below still run)")
    return Fallback(name, student, fallback, fallback_name, ok, "" if ok else reason)


def notebook_function(nb_name: str, func: str, nb_dir=None) -> Callable | None:
    """A student's exercise function from another notebook of the same folder, or None.

    Runs that notebook's cell tagged ``imports`` and its cells tagged ``exercise`` in a
    fresh namespace (the rest of the notebook is not run), with
    :func:`dtscal_lib.teaching.release.notebook_functions`: the student's code or the
    ``NotImplementedError`` stub. ``nb_dir`` defaults to the current folder (where Jupyter
    runs the notebook: the student's workspace). Prints why and returns None when the
    function cannot be loaded.
    """
    from ..release import notebook_functions

    path = Path.cwd() / nb_name if nb_dir is None else Path(nb_dir) / nb_name
    if not path.exists():
        print(f"{path.name} is not in {path.parent}; cannot load your `{func}` from it")
        return None
    try:
        return notebook_functions(path, [func])[func]
    except DtscalError as exc:
        print(f"could not load your `{func}` from {path.name}: {exc}")
        return None
