"""The live frame loop shared by the calibrator and the extrinsic tool.

One background thread asks the source for its newest frame (never a queue: a slow step
skips frames, it does not fall behind), hands it to the tool's ``on_frame`` and reports
changes of the source's state to ``on_status``. An exception in a tool's step is counted
and shown as one line; it never ends the loop and never prints a traceback.

:class:`DisplayPacer` keeps the browser from falling behind: at most one live image is on
its way to the page; while it is, the newest processed frame waits (older ones are dropped)
and goes out as soon as the page says it has displayed the previous one. Without that, a
kernel that processes frames faster than a busy browser displays them fills the websocket
with images, and the latency a student sees grows without bound.
"""

from __future__ import annotations

import threading
import time
from collections import Counter, deque
from typing import Any, Callable


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

    def idle(self, seconds: float) -> None:
        """Rest the loop thread (a tool with nothing to do for a while); ``stop`` ends the rest."""
        if threading.current_thread() is self._thread:
            self._stop.wait(seconds)

    def longest_gap(self, since: float) -> float:
        """Longest time (s) between two displayed frames after ``since`` (perf_counter)."""
        t = [x for x in list(self.display_times) if x >= since]
        return max((b - a for a, b in zip(t, t[1:])), default=0.0)


class DisplayPacer:
    """Send live images to the browser no faster than it displays them, always the newest.

    ``show(payload)`` puts one image (and whatever goes with it) into the widgets. The loop
    calls :meth:`offer` with every processed frame; the front end calls :meth:`ack` with the
    token of each image it has displayed (see :func:`ack_widgets`); an image replaced in the
    page before it loaded is never acknowledged, the next acknowledgement clears it.

    An offered frame is shown at once unless the page is behind: ``window`` images are in
    flight, or the oldest image in flight was sent longer ago than the lag limit (three times
    the shortest recent round trip, at least ``min_lag`` seconds). Then the frame waits as the
    one pending frame (a newer one replaces, i.e. drops, it) and :meth:`ack` shows it. So when
    the page keeps up nothing waits (the page itself skips an image replaced before it
    loaded, which is the freshest way to drop), and when it does not (a slow link, a stalled
    page), the images do not pile up in the websocket: the lag stays bounded.

    Measured (README, "Live calibrator"): on one machine the page keeps up, and strict
    one-image-at-a-time pacing only added the acknowledgement's round trip to every image,
    while each acknowledgement (a message to the kernel, its busy/idle status, the echo)
    cost the loaded machine more than it saved. So the page acknowledges at most twice a
    second and the pacer is a safety net against a real backlog, not a metronome.

    Until the first acknowledgement arrives (no browser: a benchmark, a test; a front end that
    does not run the hook) every frame is shown at once; an image unacknowledged for
    ``timeout`` seconds no longer holds the next back.

    Parameters
    ----------
    show : called with a payload, in the loop thread or in the thread that calls ``ack``
    window : images in flight at most
    min_lag : seconds; the lag limit is never shorter
    timeout : seconds after which an unacknowledged image is forgotten
    """

    WINDOW = 64
    MIN_LAG = 1.0
    TIMEOUT = 3.0

    def __init__(self, show: Callable[[Any], None], *, window: int | None = None, min_lag: float | None = None,
                 timeout: float | None = None):
        self._show = show
        self.window = max(1, int(self.WINDOW if window is None else window))
        self.min_lag = float(self.MIN_LAG if min_lag is None else min_lag)
        self.timeout = float(self.TIMEOUT if timeout is None else timeout)
        self._lock = threading.Lock()
        self._show_lock = threading.Lock()  # one widget update at a time, in whichever thread
        self._seq = 0
        self._in_flight: deque[tuple[int, float]] = deque()  # (token, time sent), oldest first
        self._pending: tuple[int, Any] | None = None
        self._last_shown = 0
        self.acks = 0  # acknowledgements received (any token): the front end runs the hook
        self.shown = 0
        self.held = 0  # frames that had to wait for the page
        self.dropped = 0  # frames replaced while waiting for the page (never shown)
        self.round_trips: deque[float] = deque(maxlen=32)  # s, from show to its acknowledgement

    def lag_limit(self) -> float:
        """Seconds the oldest image in flight may be on its way before the next one waits."""
        rt = list(self.round_trips)
        return max(self.min_lag, 3.0 * min(rt)) if rt else max(self.min_lag, self.timeout / 2)

    @property
    def pacing(self) -> bool:
        """True once the front end acknowledges images (from then on the page's lag is bounded)."""
        return self.acks > 0

    def next_token(self) -> int:
        """A new token for an image (its ``dtscal-shown-<token>`` class, echoed by the page)."""
        with self._lock:
            self._seq += 1
            return self._seq

    def _ready(self, now: float) -> bool:
        fl = self._in_flight
        while fl and now - fl[0][1] >= self.timeout:  # lost acknowledgements do not hold the view
            fl.popleft()
        if not self.acks or not fl:
            return True
        return len(fl) < self.window and now - fl[0][1] < self.lag_limit()

    def offer(self, token: int, payload) -> bool:
        """Show ``payload`` now if the page is ready for it (returns True), else keep it pending."""
        with self._lock:
            now = time.monotonic()
            if self._pending is not None:  # the older pending frame is dropped: only the newest waits
                self.dropped += 1
                self._pending = None
            if not self._ready(now):
                self._pending = (token, payload)
                self.held += 1
                return False
            self._in_flight.append((token, now))
        self._do_show(token, payload)
        return True

    def ack(self, token) -> None:
        """The page displayed the image ``token``: show the pending frame, if any."""
        try:
            token = int(token)
        except (TypeError, ValueError):
            return
        with self._lock:
            self.acks += 1
            fl = self._in_flight
            if not any(t == token for t, _ in fl):  # a late acknowledgement (timed out already)
                return
            now = time.monotonic()
            while fl:  # images sent before this one and not displayed were replaced in the page
                t, sent = fl.popleft()
                if t == token:
                    self.round_trips.append(now - sent)
                    break
            nxt = None
            if self._pending is not None and self._ready(now):
                nxt, self._pending = self._pending, None
                fl.append((nxt[0], now))
        if nxt is not None:
            self._do_show(*nxt)

    def _do_show(self, token: int, payload) -> None:
        with self._show_lock:
            if token < self._last_shown:  # a newer frame got out first (the other thread): never go back
                self.dropped += 1
                return
            self._last_shown = token
            self._show(payload)
            self.shown += 1


#: installed once per page by :func:`ack_widgets`: when a live image has loaded, write its token into
#: the hidden text box of its tool, which sends it to the kernel (ipywidgets' own sync); at most one
#: acknowledgement per ``ACK_INTERVAL_MS`` and tool, the last one always sent (each costs a kernel message)
ACK_INTERVAL_MS = 500
_ACK_HOOK_JS = (
    "if(!window.__dtscalAck){window.__dtscalAck=1;document.addEventListener('load',function(e){"
    "var i=e.target;if(!i||!i.classList||!i.classList.contains('dtscal-live'))return;"
    "var c=[].find.call(i.classList,function(k){return k.indexOf('dtscal-shown-')===0;});"
    "var r=i.closest('.dtscal-tool');if(!c||!r)return;r.__ack=c.slice(13);if(r.__ackT)return;"
    "r.__ackT=setTimeout(function(){r.__ackT=null;r.__ackAt=Date.now();"
    "var a=r.querySelector('.dtscal-ack input');"
    "if(a&&a.value!==r.__ack){a.value=r.__ack;a.dispatchEvent(new Event('input',{bubbles:true}));}},"
    "Math.max(0,%d-(Date.now()-(r.__ackAt||0))));},true);}" % ACK_INTERVAL_MS
)


def ack_widgets(pacer: DisplayPacer):
    """Hidden widgets that carry the page's acknowledgements to ``pacer`` (put them in the tool's
    box, whose ``_dom_classes`` must include ``dtscal-tool``).

    A text box the page writes the token of each displayed image into (ipywidgets syncs it to the
    kernel), and an HTML snippet whose ``onerror`` installs the page's load listener once (plain
    ipywidgets: no front-end extension to install).
    """
    import html

    import ipywidgets as w

    box = w.Text(value="", continuous_update=True, layout=w.Layout(display="none"))
    box.add_class("dtscal-ack")
    box.observe(lambda ch: pacer.ack(ch["new"]), "value")
    hook = w.HTML(f'<img alt="" src="data:," style="display:none" onerror="{html.escape(_ACK_HOOK_JS)}">',
                  layout=w.Layout(display="none"))
    return w.HBox([box, hook], layout=w.Layout(display="none"))
