"""The live frame loop shared by the calibrator and the extrinsic tool.

One background thread asks the source for its newest frame (never a queue: a slow step
skips frames, it does not fall behind), hands it to the tool's ``on_frame`` and reports
changes of the source's state to ``on_status``. An exception in a tool's step is counted
and shown as one line; it never ends the loop and never prints a traceback.
"""

from __future__ import annotations

import threading
import time
from collections import Counter, deque
from typing import Callable


class FrameLoop:
    """Pull the newest frame of ``source`` and process it in a daemon thread.

    Parameters
    ----------
    source : a started or unstarted live source (``latest``, ``status``, ``reconnect``, ``close``)
    on_frame : called with each new good frame (in the loop thread); returns False when it skipped
        the frame (not displayed)
    on_status : called with the source's ``LiveStatus`` whenever its state or message changes
    """

    def __init__(self, source, on_frame: Callable, on_status: Callable, *, poll: float = 0.25):
        self.source = source
        self.on_frame = on_frame
        self.on_status = on_status
        self.poll = poll
        self.errors: Counter = Counter()
        self.last_error = ""
        self.shown = 0
        self.display_times: deque[float] = deque(maxlen=4096)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._last_index = -1
        self._last_status = None

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def start(self) -> "FrameLoop":
        if not self.running:
            self.source.start()
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, daemon=True, name="dtscal-frame-loop")
            self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=3.0)
        self._thread = None

    def close(self) -> None:
        self.stop()
        try:
            self.source.close()
        except Exception:  # closing a dead source is not an error for the user
            pass

    def reconnect(self) -> None:
        """Re-open the source (replays a recording, re-subscribes a topic) and go on."""
        self.stop()
        self.source.reconnect()
        self._last_index = -1
        self._last_status = None
        self.start()

    def step(self, frame) -> None:
        """Process one frame now, in the caller's thread (the loop body; tests and benchmarks)."""
        try:
            shown = self.on_frame(frame) is not False  # a tool returns False for a frame it skipped
        except Exception as exc:  # one bad step is counted, never fatal
            self.errors[type(exc).__name__] += 1
            self.last_error = f"{type(exc).__name__}: {exc}"
            shown = False
        if shown:
            self.shown += 1
            self.display_times.append(time.perf_counter())

    def _check_status(self) -> None:
        st = self.source.status
        key = (st.state, st.message, tuple(sorted(st.bad.items())))
        if key != self._last_status:
            self._last_status = key
            try:
                self.on_status(st)
            except Exception as exc:
                self.errors[type(exc).__name__] += 1
                self.last_error = f"{type(exc).__name__}: {exc}"

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                frame = self.source.latest(after=self._last_index, timeout=self.poll)
            except Exception as exc:  # a broken source reports through its status
                self.errors[type(exc).__name__] += 1
                self.last_error = f"{type(exc).__name__}: {exc}"
                frame = None
            self._check_status()
            if frame is None:
                if self.source.status.state in ("ended", "error"):
                    self._stop.wait(self.poll)
                continue
            if frame.index < self._last_index:  # the source restarted its numbering
                self._last_index = -1
            self._last_index = frame.index
            self.step(frame)

    def longest_gap(self, since: float) -> float:
        """Longest time (s) between two displayed frames after ``since`` (perf_counter)."""
        t = [x for x in list(self.display_times) if x >= since]
        return max((b - a for a, b in zip(t, t[1:])), default=0.0)
