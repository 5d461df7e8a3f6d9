"""CALIBRATE in a helper process, so that the live image never waits for the solver.

In a thread of the kernel, the Python-heavy solver and the frame loop take turns on the GIL:
every time the solver calls into OpenCV it gives the GIL away and waits up to the interpreter's
switch interval to get it back, thousands of times per calibration (seconds, during which the
image stutters). :class:`SolverProcess` runs :func:`dtscal_lib.session.calibrate_without_outlier_views`
in a child Python (``python -m dtscal_lib.ui.solver``) started ahead of time; requests and answers
are pickles over its stdin/stdout (a private pipe between two processes of the same kit).
"""

from __future__ import annotations

import os
import pickle
import struct
import subprocess
import sys
import threading
from pathlib import Path

from ..errors import DtscalError
from ..session import assess_quality

_HEADER = struct.Struct("<Q")


def _send(stream, obj) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_HEADER.pack(len(data)) + data)
    stream.flush()


def _receive(stream):
    head = stream.read(_HEADER.size)
    if len(head) < _HEADER.size:
        raise EOFError("the calibration process ended")
    (n,) = _HEADER.unpack(head)
    data = stream.read(n)
    if len(data) < n:
        raise EOFError("the calibration process ended mid-answer")
    return pickle.loads(data)


class SolverProcess:
    """A child process that calibrates on request; :meth:`calibrate` raises ``OSError``/``EOFError``
    when the process is gone (the caller then calibrates in its own process)."""

    def __init__(self):
        root = str(Path(__file__).resolve().parents[2])
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([root, os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
        self._proc = subprocess.Popen([sys.executable, "-m", "dtscal_lib.ui.solver"], stdin=subprocess.PIPE,
                                      stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env)
        self._lock = threading.Lock()
        self._ready = threading.Event()
        self._failed = False
        threading.Thread(target=self._handshake, daemon=True, name="dtscal-solver-start").start()

    def _handshake(self) -> None:
        try:
            self._failed = _receive(self._proc.stdout) != "ready"
        except (OSError, EOFError, pickle.UnpicklingError):
            self._failed = True
        self._ready.set()

    def ready(self, wait: float = 0.0) -> bool:
        """True once the child has imported the solver (waiting up to ``wait`` seconds)."""
        self._ready.wait(wait)
        return self._ready.is_set() and not self._failed

    @property
    def alive(self) -> bool:
        return self._proc.poll() is None and not self._failed

    def _ask(self, request):
        if not self.ready(wait=120.0):
            raise EOFError("the calibration process did not start")
        with self._lock:
            _send(self._proc.stdin, request)
            kind, value = _receive(self._proc.stdout)
        if kind == "ok":
            return value
        raise DtscalError(value)

    def calibrate(self, object_points, image_points, image_size, model: str, skew: bool = False):
        """``(CalibrationResult, dropped)`` computed in the child; DtscalError as the solver raised it."""
        return self._ask(("calibrate", list(object_points), list(image_points), tuple(image_size), model,
                          bool(skew)))

    def assess(self, result):
        """:func:`assess_quality` of a result, computed in the child."""
        return self._ask(("assess", result))

    def close(self) -> None:
        if self._proc.poll() is None:
            try:
                self._proc.stdin.close()
                self._proc.wait(timeout=3)
            except (OSError, subprocess.TimeoutExpired):
                self._proc.kill()
                self._proc.wait(timeout=3)


#: the calibration process runs this much nicer than the kernel: on a busy machine (two cores, a
#: browser, the Jupyter server) the live image wins the CPU; on an idle one it changes nothing
NICENESS = 5


def _serve() -> None:
    try:
        os.nice(NICENESS)
    except (AttributeError, OSError):  # no nice() on this platform: the same, at normal priority
        pass
    from ..session import calibrate_without_outlier_views

    out, inp = sys.stdout.buffer, sys.stdin.buffer
    _send(out, "ready")
    while True:
        try:
            request = _receive(inp)
        except EOFError:
            return
        try:
            if request[0] == "assess":
                answer = ("ok", assess_quality(request[1]))
            else:
                _, obj, img, size, model, skew = request
                answer = ("ok", calibrate_without_outlier_views(obj, img, size, model=model, skew=skew))
        except DtscalError as exc:
            answer = ("error", str(exc))
        except Exception as exc:  # numerical breakdown: a message for the UI, never a traceback
            answer = ("error", f"{type(exc).__name__}: {exc}; collect more varied samples and try again")
        _send(out, answer)


if __name__ == "__main__":
    _serve()
