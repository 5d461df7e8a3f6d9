"""The live calibrator's work off the frame loop: CALIBRATE of its session, and the undistorted preview's maps.

:class:`BackgroundCalibration` runs :meth:`dtscal_lib.session.IntrinsicSession.calibrate` in a thread,
with the solver in the calibration process (:class:`~dtscal_lib.ui.solver.SolverProcess`, started
ahead of time) when it runs, else in this process; the verdict follows the result (it can take longer).
:class:`PreviewMaps` makes the undistortion maps of the preview in a helper thread: a frame never waits
for them. Both report to the widgets through callbacks; neither holds a widget.
"""

from __future__ import annotations

import threading
import time

import cv2

from ..errors import DtscalError
from ..session import MIN_SAMPLES, assess_quality
from .render import rectification_maps_fast
from .solver import SolverProcess


class BackgroundCalibration:
    """CALIBRATE of ``session`` in a thread; ``on_result(result)``, ``on_error(message)``, ``on_verdict(quality)``
    and ``on_end()`` are called from that thread."""

    def __init__(self, session, *, on_result, on_error, on_verdict, on_end):
        self.session = session
        self.on_result, self.on_error, self.on_verdict, self.on_end = on_result, on_error, on_verdict, on_end
        self.solver: SolverProcess | None = None
        self.job: threading.Thread | None = None
        self.busy = False
        self.error: str | None = None
        self.seconds = float("nan")

    def prepare(self, wait: float = 0.0) -> bool:
        """Start the calibration process ahead of CALIBRATE; True when it is ready (waiting up to ``wait`` s)."""
        if self.solver is None or not self.solver.alive:
            try:
                self.solver = SolverProcess()
            except OSError:  # no subprocesses here: CALIBRATE runs in a thread of this process
                self.solver = None
                return False
        return self.solver.ready(wait)

    def start(self, prepare=None) -> threading.Thread:
        """CALIBRATE now (the job already running, if one is); ``prepare`` replaces :meth:`prepare`."""
        with self.session.lock:
            if not self.busy:
                self.busy = True
                self.job = threading.Thread(target=self._run, args=(prepare or self.prepare,), daemon=True,
                                            name="dtscal-calibrate")
                self.job.start()
            return self.job

    def _verdict(self, result):
        if self.solver is not None:
            try:
                return self.solver.assess(result)
            except (OSError, EOFError, DtscalError):
                pass
        return assess_quality(result)

    def _run(self, prepare) -> None:
        t0 = time.perf_counter()
        result = None
        try:
            try:
                result = self.session.calibrate(solver=self.solver if prepare() else None)
            except (OSError, EOFError):  # the calibration process is gone: calibrate in this one
                self.solver = None
                result = self.session.calibrate()
        except DtscalError as exc:
            self.error = str(exc)
            self.on_error(f"CALIBRATE failed: {exc}.")
        except Exception as exc:  # numerical breakdown: a message, never a traceback
            self.error = f"{type(exc).__name__}: {exc}"
            self.on_error(f"CALIBRATE failed ({self.error}); collect more varied samples and try again")
        else:
            self.error = None
            self.on_result(result)
        finally:
            self.seconds = time.perf_counter() - t0
        try:
            if result is not None:  # the verdict follows; it can take longer than the calibration
                quality = self._verdict(result)
                with self.session.lock:
                    current = self.session.result is result
                    if current:
                        self.session.quality(known=quality)
                if current:
                    self.on_verdict(result, quality)
        finally:
            with self.session.lock:
                self.busy = False
            self.on_end()

    def can_start(self) -> bool:
        """CALIBRATE is enabled: ROS's rule, at least :data:`~dtscal_lib.session.MIN_SAMPLES`, no job running."""
        with self.session.lock:
            tracker = self.session.tracker
            n = 0 if tracker is None else len(tracker.samples)
            return not self.busy and tracker is not None and tracker.ready() and n >= MIN_SAMPLES

    def close(self) -> None:
        if self.solver is not None:
            self.solver.close()
            self.solver = None


class PreviewMaps:
    """Undistortion maps of the current result at the slider's alpha, made in a helper thread."""

    def __init__(self, lock: threading.RLock):
        self._lock = lock
        self.maps = None
        self.key = None
        self._builder: threading.Thread | None = None

    def build(self, result, alpha: float, current) -> None:
        """Make the maps of ``result`` at ``alpha``; kept if ``current()`` is still ``result``."""
        maps = rectification_maps_fast(result.camera().with_alpha(alpha))
        with self._lock:
            if current() is result:
                self.maps, self.key = maps, (id(result), round(alpha, 3))

    def undistort(self, img, result, alpha: float, current):
        """The undistorted frame, or None while the maps for ``result`` are being made (in a helper thread)."""
        with self._lock:
            maps, key = self.maps, self.key
        if result is None:
            return None
        if key != (id(result), round(alpha, 3)) and not (self._builder and self._builder.is_alive()):
            self._builder = threading.Thread(target=self.build, args=(result, alpha, current), daemon=True,
                                             name="dtscal-preview-maps")
            self._builder.start()
        if maps is None or key[0] != id(result):
            return None
        return cv2.remap(img, maps[0], maps[1], cv2.INTER_LINEAR)
