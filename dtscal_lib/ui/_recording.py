"""TEMPORARY private adapter: a recording played as a live source (pinned LiveSource interface).

Stands in for ``dtscal_lib.sources.live`` (issue 10a) until it lands; delete this file then.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from dataclasses import dataclass, field

from ..sources import Frame, open_source


@dataclass
class LiveStatus:
    state: str
    message: str
    frames: int
    bad: dict = field(default_factory=dict)


class LiveSource:
    def __init__(self, spec: str, *, realtime: bool = True, topic: str | None = None, loop: bool = False):
        self.spec = str(spec)
        self._src = open_source(self.spec, topic=topic)
        self.topic = getattr(self._src, "topic", None)
        self.realtime, self.loop = realtime, loop
        self._cond = threading.Condition()
        self._latest: Frame | None = None
        self._status = LiveStatus("connecting", f"opening {self.spec}", 0, {})
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._count = 0

    @property
    def status(self) -> LiveStatus:
        with self._cond:
            s = self._status
            return LiveStatus(s.state, s.message, s.frames, dict(s.bad))

    def start(self) -> "LiveSource":
        if self._thread is None or not self._thread.is_alive():
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, daemon=True, name="dtscal-recording")
            self._thread.start()
        return self

    def _run(self) -> None:
        bad: Counter = Counter()
        try:
            while not self._stop.is_set():
                t0 = None
                s0 = None
                for f in self._src:
                    if self._stop.is_set():
                        return
                    if self.realtime:
                        now = time.monotonic()
                        if t0 is None:
                            t0, s0 = now, f.stamp
                        wait = (f.stamp - s0) - (now - t0)
                        if wait > 0:
                            self._stop.wait(min(wait, 1.0))
                    with self._cond:
                        if f.ok:
                            self._latest = Frame(self._count, f.stamp, f.image, None, f.name)
                            self._latest.arrival = time.time()
                            self._count += 1
                        else:
                            bad[f.error.reason if f.error else "unreadable"] += 1
                        self._status = LiveStatus("running", f"playing {self.spec}", self._count, dict(bad))
                        self._cond.notify_all()
                if not self.loop:
                    break
            with self._cond:
                self._status = LiveStatus("ended", f"the recording {self.spec} ended", self._count, dict(bad))
                self._cond.notify_all()
        except Exception as exc:  # the adapter must never raise into the UI
            with self._cond:
                self._status = LiveStatus("error", f"{type(exc).__name__}: {exc}", self._count, dict(bad))
                self._cond.notify_all()

    def latest(self, after: int = -1, timeout: float = 1.0) -> Frame | None:
        deadline = time.monotonic() + timeout
        with self._cond:
            while self._latest is None or self._latest.index <= after:
                left = deadline - time.monotonic()
                if left <= 0 or self._status.state in ("ended", "error"):
                    return None
                self._cond.wait(left)
            return self._latest

    def reconnect(self) -> None:
        self.close()
        self.start()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        self._thread = None

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.close()


def open_live(spec: str, *, realtime: bool = True, topic: str | None = None, loop: bool = False) -> LiveSource:
    return LiveSource(spec, realtime=realtime, topic=topic, loop=loop)
