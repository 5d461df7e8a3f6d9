"""Live camera sources: the newest frame of a recording, a robot over DTPS or ROS 1, a webcam or a stream.

One function, :func:`open_live`, and one interface, :class:`LiveSource`, whatever the camera::

    with open_live("data/session/intrinsics.bag") as cam:      # or "ros:autobot01", "device:0", a URL
        frame = cam.latest()                                     # the newest good frame, or None
        while frame is not None:
            ...                                                  # detect, draw, show
            frame = cam.latest(after=frame.index)

A background thread (and, for ROS, a helper process) receives frames and keeps **only the newest
one**: a consumer slower than the camera skips frames instead of falling behind, and memory does
not grow however long the session runs. Frames that do not decode are counted in
``status.bad`` by reason and never handed out. When the camera goes away (the recording ends, the
ROS master is killed, the webcam is unplugged) ``status`` says so in a sentence, the last frame
stays readable, and :meth:`LiveSource.reconnect` starts receiving again.

======================  =====================================================================
spec                    frames from
======================  =====================================================================
``run.bag`` (video,     the recording (:func:`~dtscal_lib.sources.open_source`), at its recorded
folder, glob)           rate (``realtime=True``) or as fast as it decodes; ``loop=True`` repeats it
``dtps:ROBOT``          the robot's camera over DTPS, ``ROBOT/sensor/camera/front_center/jpeg`` on
                        its switchboard ``ROBOT.local:11911``, as ``duckietown-sdk`` reads it
                        (``dtps:ROBOT/SENSOR@HOST:PORT``: :mod:`dtscal_lib.dtps_link`)
``ros:ROBOT``           ``/ROBOT/camera_node/image/compressed`` through the master of
                        ``ROS_MASTER_URI`` (``topic=`` overrides the topic)
``device:N``            OpenCV ``VideoCapture(N)`` (a webcam)
``http(s)://...``,      OpenCV ``VideoCapture(url)`` (an MJPEG or RTSP stream)
``rtsp://...``
======================  =====================================================================
"""

from __future__ import annotations

import contextlib
import os
import shutil
import struct
import subprocess
import tempfile
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Self

import numpy as np

from .. import duckietown as dt
from ..errors import DtscalError, FrameError, SourceError
from .decode import decode_image
from .frame import Frame

#: the Python that runs the ROS helper: Debian's, which has rospy (override with DTSCAL_ROS_PYTHON)
ROS_PYTHON = "/usr/bin/python3"
HELPER = Path(__file__).with_name("ros_helper.py")
DEFAULT_MASTER = f"http://localhost:{dt.ROS_MASTER_PORT}"
#: a camera that sends nothing for this long is reported as gone
STALL_SECONDS = 2.0


@dataclass
class LiveStatus:
    """What a live source is doing, for a status line.

    ``state`` is ``"connecting"``, ``"running"``, ``"ended"`` or ``"error"``; ``message`` a sentence
    that says what to do; ``frames`` counts frames received (good and bad); ``bad`` maps a reason
    (``"corrupt_jpeg"``, ``"empty"``, ...) to the number of frames skipped for it.
    """

    state: str
    message: str
    frames: int
    bad: dict = field(default_factory=dict)


class LiveSource:
    """Base class: a background receiver that keeps only the newest good :class:`Frame`.

    Subclasses implement :meth:`_run` (receive until ``stop`` is set, calling :meth:`_push` /
    :meth:`_push_bad`) and may override :meth:`_halt` to unblock it.
    """

    kind = ""
    #: recordings and cameras: consecutive frames are near duplicates (ROS's coverage rule applies)
    is_stream = True
    topic: str | None = None

    def __init__(self, spec: str):
        self.spec = spec
        self._cond = threading.Condition()
        self._newest: Frame | None = None
        self._received = 0
        self._bad: Counter = Counter()
        self._state, self._message = "connecting", f"connecting to {spec}"
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._closed = False
        self._listeners: list = []

    # ------------------------------------------------------------------ public
    def add_status_listener(self, callback) -> None:
        """Call ``callback(LiveStatus)`` (in the receiver's thread) whenever the state or message changes.

        The status hook of a UI: its status line follows the source at once, frames or not (a
        source that cannot connect says why before any frame could arrive). A failing callback
        is ignored: it must never stop the receiver.
        """
        self._listeners.append(callback)

    def start(self) -> LiveSource:
        """Begin receiving in the background (no-op when already receiving); returns self."""
        if self._closed:
            raise SourceError(f"{self.describe()} was closed; open it again with open_live({self.spec!r})")
        if self._thread is not None and self._thread.is_alive():
            return self
        self._stop = threading.Event()
        self._set_state("connecting", f"connecting to {self.describe()}")
        self._thread = threading.Thread(target=self._worker, args=(self._stop,), daemon=True,
                                        name=f"dtscal-live-{self.kind}")
        self._thread.start()
        return self

    def latest(self, after: int = -1, timeout: float = 1.0) -> Frame | None:
        """The newest good frame whose ``index`` is greater than ``after``, waiting up to ``timeout`` s.

        Returns None when no such frame arrives in time, or at once when the source has ended or
        failed and has nothing newer (look at :attr:`status`). Older frames are never queued.
        """
        deadline = time.monotonic() + max(0.0, float(timeout))
        with self._cond:
            while True:
                f = self._newest
                if f is not None and f.index > after:
                    return f
                left = deadline - time.monotonic()
                if left <= 0 or self._state in ("ended", "error"):
                    return None
                self._cond.wait(left)

    @property
    def status(self) -> LiveStatus:
        with self._cond:
            return LiveStatus(self._state, self._message, self._received, dict(self._bad))

    def reconnect(self) -> None:
        """Stop receiving and start again (the frame count and the newest frame are kept)."""
        self._shutdown()
        self.start()

    def close(self) -> None:
        """Stop receiving and release the camera / helper process. Safe to call twice."""
        self._closed = True
        self._shutdown()

    def describe(self) -> str:
        return self.spec

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self):  # pragma: no cover - best effort at interpreter exit
        with contextlib.suppress(Exception):
            self._stop.set()
            self._halt()

    def __repr__(self) -> str:
        s = self.status
        return f"<{type(self).__name__} {self.describe()} {s.state}, {s.frames} frames>"

    # ------------------------------------------------------------------ for subclasses
    def _run(self, stop: threading.Event) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _halt(self) -> None:
        """Unblock :meth:`_run` (kill a helper, release a capture); called on close/reconnect."""

    def _push(self, image: np.ndarray, stamp: float, name: str, arrival: float | None = None) -> None:
        arrival = time.time() if arrival is None else arrival
        with self._cond:
            f = Frame(index=self._received, stamp=float(stamp), image=image, error=None, name=name,
                      arrival=arrival)
            self._received += 1
            self._newest = f
            if self._state != "running":
                self._state, self._message = "running", f"receiving frames from {self.describe()}"
            self._cond.notify_all()

    def _push_bad(self, reason: str) -> None:
        with self._cond:
            self._received += 1
            self._bad[reason] += 1

    def _push_bytes(self, data: bytes, stamp: float, name: str) -> None:
        """Decode an encoded frame with the guarded decoder; count it as bad when it does not decode."""
        arrival = time.time()  # the frame's arrival: decoding is part of its latency
        try:
            image = decode_image(data)
        except FrameError as exc:
            self._push_bad(exc.reason)
            return
        self._push(image, stamp, name, arrival)

    def _set_state(self, state: str, message: str) -> None:
        with self._cond:
            changed = (self._state, self._message) != (state, message)
            self._state, self._message = state, message
            self._cond.notify_all()
        if changed and self._listeners:
            st = self.status
            for callback in list(self._listeners):
                try:
                    callback(st)
                except Exception:  # noqa: BLE001 (a UI's bug must not stop the receiver)
                    pass

    # ------------------------------------------------------------------ internals
    def _worker(self, stop: threading.Event) -> None:
        try:
            self._run(stop)
        except DtscalError as exc:
            if not stop.is_set():
                self._set_state("error", f"{exc}; press Reconnect to try again")
        except Exception as exc:  # noqa: BLE001 (a receiver bug must show as a status, never kill the notebook)
            if not stop.is_set():
                self._set_state("error", f"{self.describe()} stopped: {type(exc).__name__}: {exc}; "
                                         "press Reconnect to try again")

    def _shutdown(self) -> None:
        self._stop.set()
        self._halt()
        t = self._thread
        if t is not None and t is not threading.current_thread():
            t.join(timeout=5.0)
        self._thread = None
        with self._cond:
            if self._state in ("connecting", "running"):
                self._state, self._message = "ended", f"stopped receiving from {self.describe()}"
            self._cond.notify_all()


# ---------------------------------------------------------------------- recordings
class RecordingLive(LiveSource):
    """A recording played as if it were a camera (see :func:`open_live`)."""

    kind = "recording"

    def __init__(self, spec: str, *, realtime: bool = True, topic: str | None = None, loop: bool = False):
        super().__init__(spec)
        from . import open_source

        self._source = open_source(spec, topic=topic)  # fails now, with the fix, on a bad path
        self.topic = getattr(self._source, "topic", None)
        self.is_stream = bool(self._source.is_stream)
        self.realtime, self.loop = bool(realtime), bool(loop)

    def describe(self) -> str:
        return f"recording {self._source.describe()}"

    def _run(self, stop: threading.Event) -> None:
        while not stop.is_set():
            t0 = s0 = None
            for frame in self._source:
                if stop.is_set():
                    return
                if self.realtime:
                    now = time.monotonic()
                    if t0 is None or not (0 <= frame.stamp - s0 <= (now - t0) + 5.0):
                        t0, s0 = now, frame.stamp  # first frame, or a jump in the stamps: re-anchor
                    wait = t0 + (frame.stamp - s0) - now
                    if wait > 0 and stop.wait(wait):
                        return
                if frame.ok:
                    self._push(frame.image, frame.stamp, frame.name)
                else:
                    self._push_bad(frame.error.reason)
            if not self.loop:
                break
        if not stop.is_set():
            self._set_state("ended", f"the recording ended after {self.status.frames} frames "
                                     f"({self._source.describe()}); press Reconnect to play it again")


# ---------------------------------------------------------------------- OpenCV captures
class CaptureLive(LiveSource):
    """A webcam (``device:N``) or a network stream (URL) read with OpenCV's ``VideoCapture``."""

    def __init__(self, spec: str):
        super().__init__(spec)
        self.kind = "device" if spec.lower().startswith("device:") else "stream"
        if self.kind == "device":
            text = spec.split(":", 1)[1]
            if not text.strip().isdigit():
                raise SourceError(f"{spec!r}: a camera is device:N with N a number (device:0 is the first webcam)")
            self.target: int | str = int(text)
        else:
            self.target = spec

    def describe(self) -> str:
        return f"camera {self.target}" if self.kind == "device" else f"stream {self.spec}"

    def _open(self):
        import cv2

        return cv2.VideoCapture(self.target)

    def _run(self, stop: threading.Event) -> None:
        # the capture is used and released by this thread only: releasing it from another thread
        # while read() blocks can crash OpenCV's FFmpeg backend
        cap = self._open()
        try:
            self._read(cap, stop)
        finally:
            if cap is not None:
                cap.release()

    def _read(self, cap, stop: threading.Event) -> None:
        if cap is None or not cap.isOpened():
            what = ("is it plugged in, and not in use by another program (a video call)?" if self.kind == "device"
                    else "check the address and that the stream is running.")
            self._set_state("error", f"could not open {self.describe()}: {what} Press Reconnect to try again")
            return
        last_good = time.monotonic()
        n = 0
        while not stop.is_set():
            ok, image = cap.read()
            if stop.is_set():
                return
            if ok and image is not None and image.ndim == 3 and image.size:
                self._push(image, time.time(), f"{self.describe()}#{n}")
                n += 1
                last_good = time.monotonic()
                continue
            if ok:  # a frame came, but an odd one
                self._push_bad("empty" if image is None or image.size == 0 else "odd_frame")
            if not ok and (self.kind == "stream" or time.monotonic() - last_good > STALL_SECONDS):
                break
            stop.wait(0.02)
        if stop.is_set():
            return
        if self.kind == "device":
            self._set_state("error", f"{self.describe()} stopped sending frames (unplugged?); plug it back in "
                                     "and press Reconnect")
        else:
            self._set_state("ended", f"{self.describe()} ended or the connection dropped after {n} frames; "
                                     "press Reconnect to try again")


# ---------------------------------------------------------------------- ROS 1
def ros_python() -> str:
    """The interpreter with rospy; raises :class:`SourceError` with the fix when there is none."""
    py = os.environ.get("DTSCAL_ROS_PYTHON", ROS_PYTHON)
    probe = _ros_probe(py)
    if probe:
        raise SourceError(
            f"ROS 1 is not available to {py} ({probe}). On Debian/Ubuntu install it with "
            "`sudo scripts/install-ros.sh` (packages python3-rospy python3-sensor-msgs), or run the kit "
            "inside the Duckietown `dts` shell / a ROS noetic container; set DTSCAL_ROS_PYTHON to another "
            "python that can `import rospy`"
        )
    return py


_PROBED: dict[str, str | None] = {}


def _ros_probe(py: str) -> str | None:
    if py not in _PROBED:
        if not (os.path.isabs(py) and os.path.exists(py)) and shutil.which(py) is None:
            _PROBED[py] = "no such program"
        else:
            try:
                r = subprocess.run([py, "-c", "import rospy, sensor_msgs.msg, sensor_msgs.srv"],
                                   env=_clean_env(DEFAULT_MASTER), capture_output=True, timeout=60, check=False)
                _PROBED[py] = None if r.returncode == 0 else (r.stderr.decode(errors="replace").strip()
                                                              .splitlines() or ["import failed"])[-1]
            except (OSError, subprocess.TimeoutExpired) as exc:
                _PROBED[py] = str(exc)
    return _PROBED[py]


def master_uri(uri: str | None = None) -> str:
    """The ROS master to use: ``uri``, else ``$ROS_MASTER_URI``, else ``http://localhost:11311``."""
    uri = (uri or os.environ.get("ROS_MASTER_URI") or DEFAULT_MASTER).strip()
    if not uri.startswith("http://"):
        raise SourceError(f"ROS master URI {uri!r} must look like "
                          f"http://{dt.DTPS_HOST.format(robot='ROBOT')}:{dt.ROS_MASTER_PORT}")
    return uri


def _clean_env(uri: str) -> dict[str, str]:
    """Environment for a ROS process: no venv; the ROS network variables kept.

    Debian's ROS needs nothing else. In a shell where a ROS distribution's ``setup.bash`` was
    sourced (``ROS_DISTRO`` is set, e.g. a ROS noetic container) its paths are kept too.
    """
    env = {"PATH": "/usr/bin:/bin:/usr/local/bin", "LANG": "C.UTF-8", "PYTHONUNBUFFERED": "1",
           "ROS_MASTER_URI": uri, "HOME": os.environ.get("HOME") or tempfile.gettempdir()}
    keep = ["ROS_HOSTNAME", "ROS_IP", "ROS_HOME", "ROS_LOG_DIR"]
    if os.environ.get("ROS_DISTRO"):
        keep += ["ROS_DISTRO", "ROS_PACKAGE_PATH", "ROS_ROOT", "ROS_ETC_DIR", "PYTHONPATH", "LD_LIBRARY_PATH",
                 "CMAKE_PREFIX_PATH"]
        venv = os.environ.get("VIRTUAL_ENV")
        env["PATH"] = os.pathsep.join(p for p in os.environ.get("PATH", env["PATH"]).split(os.pathsep)
                                      if not (venv and p.startswith(venv)))
    for k in keep:
        if os.environ.get(k):
            env[k] = os.environ[k]
    env.setdefault("ROS_LOG_DIR", os.path.join(tempfile.gettempdir(), "dtscal-ros-log"))
    return env


def run_ros_helper(args: list[str], *, master: str | None = None, stdin: bytes | None = None,
                   timeout: float = 30.0) -> subprocess.CompletedProcess:
    """Run the helper once (e.g. a service call) and return its completed process."""
    py = ros_python()
    return subprocess.run([py, str(HELPER), *args], input=stdin, env=_clean_env(master_uri(master)),
                          capture_output=True, timeout=timeout, check=False)


def _read_exact(stream, n: int) -> bytes | None:
    buf = b""
    while len(buf) < n:
        chunk = stream.read(n - len(buf))
        if not chunk:
            return None
        buf += chunk
    return buf


class RosLive(LiveSource):
    """A Duckiebot's camera topic over ROS 1, through a rospy helper process (see module doc)."""

    kind = "ros"

    def __init__(self, robot: str, *, topic: str | None = None, master: str | None = None):
        if not robot and not topic:
            raise SourceError("ros: needs a robot name, e.g. ros:autobot01 (or pass topic=)")
        self.robot = robot or None
        super().__init__(f"ros:{robot}")
        self.topic = topic or dt.ros_name(dt.IMAGE_TOPIC, robot)
        if not self.topic.startswith("/"):
            raise SourceError(f"topic {self.topic!r} must start with '/'")
        self.master = master_uri(master)
        self._master_given = bool(master or os.environ.get("ROS_MASTER_URI"))
        self._python = ros_python()
        self._proc: subprocess.Popen | None = None
        self._log = tempfile.TemporaryFile()  # noqa: SIM115 (the helper's stderr, open while the source lives)

    def describe(self) -> str:
        return f"{self.topic} on {self.master}"

    def _halt(self) -> None:
        proc, self._proc = self._proc, None
        if proc is not None and proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=3)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()

    def _helper_log(self) -> str:
        try:
            self._log.seek(0)
            lines = self._log.read().decode(errors="replace").strip().splitlines()
            return " | ".join(lines[-3:])
        except (OSError, ValueError):
            return ""

    def _diagnose(self, stop: threading.Event) -> bool:
        """Say what is wrong before starting the helper; True when a ROS connection cannot work."""
        from . import ros_diagnosis as diag

        problem = diag.master_problem(self.master, uri_was_set=self._master_given) or diag.callback_problem()
        if problem:
            if not stop.is_set():
                self._set_state("error", problem)
            return True
        waiting = diag.topic_problem(self.master, self.topic, self.robot)
        if waiting and not stop.is_set():
            self._set_state("connecting", waiting)
        return False

    def _waiting_message(self, helper_message: str) -> str:
        from . import ros_diagnosis as diag

        try:
            return diag.topic_problem(self.master, self.topic, self.robot) or helper_message
        except Exception:  # noqa: BLE001 (the helper's own sentence is the fallback)
            return helper_message

    def _run(self, stop: threading.Event) -> None:
        self._log.seek(0)
        self._log.truncate()
        if self._diagnose(stop):
            return
        proc = subprocess.Popen([self._python, str(HELPER), "subscribe", self.topic], env=_clean_env(self.master),
                                stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=self._log, bufsize=0)
        self._proc = proc
        import json

        said_error = False
        n = 0
        while not stop.is_set():
            head = _read_exact(proc.stdout, 5)
            if head is None:
                break
            kind, length = head[:1], struct.unpack("!I", head[1:])[0]
            payload = _read_exact(proc.stdout, length)
            if payload is None:
                break
            if kind == b"F":
                self._push_bytes(payload[8:], struct.unpack("!d", payload[:8])[0], f"{self.topic}#{n}")
                n += 1
            elif kind == b"S":
                st = json.loads(payload.decode())
                state = st.get("state")
                if state == "error":
                    said_error = True
                    self._set_state("error", st["message"])
                elif state == "waiting":
                    self._set_state("ended" if n else "connecting",
                                    st["message"] if n else self._waiting_message(st["message"]))
                elif state == "running" and self.status.state != "running":
                    self._set_state("connecting", f"{st['message']}, but no frame arrived yet; if this lasts, set "
                                                  "ROS_IP (or ROS_HOSTNAME) to an address of this computer that "
                                                  "the robot can reach")
        if stop.is_set():
            return
        code = proc.wait()
        if not said_error:
            log = self._helper_log()
            self._set_state("error", f"the ROS helper for {self.describe()} exited (code {code})"
                                     + (f": {log}" if log else "") + "; press Reconnect to try again")

    def close(self) -> None:
        super().close()
        try:
            self._log.close()
        except OSError:
            pass


# ---------------------------------------------------------------------- DTPS
#: seconds to wait for a robot's switchboard to answer at all (a robot that is off never does)
DTPS_CONNECT_SECONDS = 5.0


class DtpsLive(LiveSource):
    """A robot's camera over DTPS (a Duckiebot on ``ente``, a DD24-B), as ``duckietown-sdk`` reads it.

    Subscribes to ``ROBOT/sensor/camera/SENSOR/jpeg`` on the robot's switchboard with ``dtps-http``; each
    message is a ``duckietown_messages`` ``CompressedImage``. A message that is not one, or whose ``format``
    is not ``jpeg``, or whose bytes do not decode, is counted in ``status.bad`` and never shown. The camera's
    ``parameters`` (the ``CameraIntrinsicCalibration`` the robot uses now) are read when connecting:
    :attr:`robot_intrinsics`. When no frame has come for :data:`STALL_SECONDS` the switchboard is asked
    again: a robot that no longer answers has gone away (``ended``). ``.dtps`` is where COMMIT goes.
    """

    kind = "dtps"

    def __init__(self, link, *, connect_seconds: float = DTPS_CONNECT_SECONDS):
        from ..dtps_link import import_dtps

        self.dtps = link
        self.robot = link.robot
        super().__init__(f"dtps:{link.robot}")
        self.topic = link.topic
        self.connect_seconds = float(connect_seconds)
        import_dtps()  # fails now, with what to install
        #: the robot's current intrinsics, as its camera publishes them (a dict of K, D, P, R,
        #: distortion_model), or None before connecting / when it publishes none
        self.robot_intrinsics: dict | None = None

    def describe(self) -> str:
        return f"{self.topic} on {self.dtps.url}"

    def _run(self, stop: threading.Event) -> None:
        import asyncio

        asyncio.run(self._session(stop))

    def _gone(self, why: str) -> str:
        return (f"{self.dtps.robot}'s switchboard at {self.dtps.url} {why}: is the robot on and on this network "
                f"(ping {self.dtps.host})? Then press Reconnect")

    async def _session(self, stop: threading.Event) -> None:
        import asyncio

        from ..dtps_link import import_dtps

        dtps, compressed_image, intrinsic_calibration = import_dtps()
        state = {"last": None}

        async def on_frame(rd) -> None:
            state["last"] = time.monotonic()
            try:
                msg = compressed_image.from_rawdata(rd)
            except Exception:  # noqa: BLE001 (duckietown_messages' DataDecodingError and pydantic's)
                self._push_bad("not_a_compressed_image")
                return
            if msg.format != "jpeg":
                self._push_bad(f"not_jpeg_{msg.format}")
                return
            self._push_bytes(bytes(msg.data), time.time(), f"{self.topic}#{self.status.frames}")

        cxt = None
        try:
            try:
                cxt = await asyncio.wait_for(dtps.context(f"dtscal-{self.dtps.robot}-{id(self)}",
                                                          urls=[self.dtps.url]), self.connect_seconds)
                camera = cxt.navigate(*self.dtps.camera)
                exists = await asyncio.wait_for((camera / dt.DTPS_CAMERA_JPEG).exists(), self.connect_seconds)
            except Exception as exc:  # noqa: BLE001 (no answer, refused, not DTPS: said in one sentence)
                why = (f"did not answer within {self.connect_seconds:g} s" if isinstance(exc, TimeoutError)
                       else f"cannot be reached ({type(exc).__name__})")
                if not stop.is_set():
                    self._set_state("error", self._gone(why))
                return
            if not exists:
                if not stop.is_set():
                    self._set_state("error", f"{self.dtps.url} answers but has no camera {self.topic}: check the "
                                             f"robot's name and camera (dtps:ROBOT/SENSOR; Duckietown's is "
                                             f"{dt.DTPS_CAMERA_SENSOR}), then press Reconnect")
                return
            with contextlib.suppress(Exception):
                rd = await asyncio.wait_for((camera / dt.DTPS_CAMERA_PARAMETERS).data_get(), self.connect_seconds)
                self.robot_intrinsics = intrinsic_calibration.from_rawdata(rd).model_dump(exclude={"header"})
            sub = await (camera / dt.DTPS_CAMERA_JPEG).subscribe(on_frame)
            self._set_state("connecting", f"subscribed to {self.describe()}, waiting for the first frame")
            state["last"] = since = time.monotonic()
            try:
                while not stop.is_set():
                    await asyncio.sleep(0.05)
                    st = self.status
                    if st.state != "running" and st.bad and time.monotonic() - since > STALL_SECONDS:
                        reasons = ", ".join(f"{k}: {v}" for k, v in sorted(st.bad.items()))
                        self._set_state("error", f"{st.frames} messages came from {self.describe()} but none is a "
                                                 f"JPEG frame ({reasons}); the kit reads the camera's JPEG "
                                                 "stream: check the robot's camera driver, then press Reconnect")
                        return
                    if time.monotonic() - state["last"] < STALL_SECONDS:
                        continue
                    try:  # silent for a while: is the robot still there?
                        await asyncio.wait_for(cxt.list(), 1.0)
                    except Exception:  # noqa: BLE001
                        if not stop.is_set():
                            self._set_state("ended", self._gone(f"stopped answering after {self.status.frames} "
                                                                "frames"))
                        return
                    state["last"] = time.monotonic()
                    if self.status.state != "running":
                        self._set_state("connecting", f"{self.dtps.url} answers but {self.topic} sends no frame: "
                                                      "is the robot's camera driver running?")
            finally:
                with contextlib.suppress(Exception):
                    await asyncio.wait_for(sub.unsubscribe(), 1.0)
        finally:
            if cxt is not None:
                with contextlib.suppress(Exception):
                    await asyncio.wait_for(cxt.aclose(), 2.0)


# ---------------------------------------------------------------------- for the command line
class LiveFrames:
    """A live source as a finite iterable of frames, for the headless pipeline.

    Yields the newest good frames until ``done()`` is true, ``max_seconds`` have passed, or the
    source ends or fails; then :attr:`stopped` says why in a sentence and :attr:`bad` counts the
    frames skipped as corrupt.
    """

    is_stream = True
    kind = "live"

    def __init__(self, spec: str, *, topic: str | None = None, max_seconds: float | None = None,
                 done=None, master_uri: str | None = None, say=None, kvstore: str | None = None):
        #: called with each new sentence on why no frame arrives yet (default: a line on stderr)
        self.say = say if say is not None else _say_on_stderr
        self.spec = spec
        self.live = open_live(spec, topic=topic, master_uri=master_uri, kvstore=kvstore)
        self.topic = self.live.topic
        #: where COMMIT goes over DTPS (a ``dtps:`` source), else None
        self.dtps = getattr(self.live, "dtps", None)
        self.max_seconds = max_seconds
        self.done = done or (lambda: False)
        self.stopped = ""
        self.bad: dict = {}

    def describe(self) -> str:
        return self.live.describe() + (f" ({self.stopped})" if self.stopped else "")

    def __len__(self) -> int:
        raise TypeError("a live source has no length")

    def __iter__(self):
        t0 = time.monotonic()
        after = -1
        said = ""
        with self.live as cam:
            while True:
                if self.done():
                    self.stopped = "stopped: enough samples"
                    break
                if self.max_seconds is not None and time.monotonic() - t0 > self.max_seconds:
                    self.stopped = f"stopped after {self.max_seconds:g} s (--max-seconds)"
                    break
                f = cam.latest(after=after, timeout=0.5)
                if f is not None:
                    after = f.index
                    yield f
                    continue
                st = cam.status
                if after < 0 and st.state == "connecting" and st.message != said:
                    said = st.message
                    if not st.message.startswith("connecting to "):
                        self.say(st.message.replace("press Reconnect", "the command goes on by itself"))
                if st.state in ("ended", "error"):
                    self.stopped = (st.message.replace("press Reconnect", "run the command again")
                                    .replace("Press Reconnect", "Run the command again"))
                    break
            self.bad = cam.status.bad
        if after < 0 and self.stopped and not self.stopped.startswith("stopped"):
            raise SourceError(f"no frame from {self.live.describe()}: {self.stopped}")


def _say_on_stderr(message: str) -> None:
    import sys

    print(f"dtscal: waiting: {message}", file=sys.stderr, flush=True)


# ---------------------------------------------------------------------- the one entry point
def is_live_spec(spec) -> bool:
    """True for ``dtps:...``, ``ros:...``, ``device:N`` and URLs: sources that only :func:`open_live` opens."""
    if not isinstance(spec, str):
        return False
    s = spec.strip().lower()
    return s.startswith(("dtps:", "ros:", "device:", "http://", "https://", "rtsp://", "rtsps://"))


def open_live(spec: str, *, realtime: bool = True, topic: str | None = None, loop: bool = False,
              master_uri: str | None = None, kvstore: str | None = None) -> LiveSource:
    """Open a camera or a recording as a :class:`LiveSource` (not started: call ``.start()`` or use ``with``).

    Parameters
    ----------
    spec : a recording (``.bag``, video, folder, glob), ``"dtps:ROBOT"``, ``"ros:ROBOT"``, ``"device:N"`` or an
        ``http(s)://`` / ``rtsp://`` stream URL
    realtime : recordings only: play at the recorded rate (True) or as fast as possible
    topic : the bag topic or ROS topic (default ``/ROBOT/camera_node/image/compressed``)
    loop : recordings only: start over at the end instead of ending
    master_uri : ROS only: the master (default ``$ROS_MASTER_URI``, else ``http://localhost:11311``)
    kvstore : DTPS only: the robot's key-value store for COMMIT (default ``http://HOST:11411/``)

    Raises
    ------
    SourceError
        A recording that cannot be opened, a malformed spec, ROS 1 missing for ``ros:``.

    Examples
    --------
    >>> with open_live("data/session/intrinsics.bag", realtime=False) as cam:   # doctest: +SKIP
    ...     f = cam.latest(timeout=5)
    """
    if not isinstance(spec, (str, os.PathLike)):
        raise SourceError(f"a live source is a string such as 'ros:ROBOT', 'device:0' or a path, "
                          f"got {type(spec).__name__}")
    text = os.fspath(spec).strip()
    low = text.lower()
    if low.startswith("dtps:"):
        from ..dtps_link import parse_dtps_spec

        if topic is not None:
            raise SourceError(f"topic= applies to bags and ROS, not to {text!r}; name the camera as "
                              "dtps:ROBOT/SENSOR")
        return DtpsLive(parse_dtps_spec(text[5:], kvstore=kvstore))
    if low.startswith("ros:"):
        robot = text[4:].strip().strip("/")
        from ..calib_files import is_robot_name

        if robot and not is_robot_name(robot):
            raise SourceError(f"{text!r}: a robot name has letters, digits and '_' only (e.g. ros:autobot01)")
        return RosLive(robot, topic=topic, master=master_uri)
    if low.startswith("device:") or is_live_spec(text):
        if topic is not None:
            raise SourceError(f"topic= applies to bags and ROS, not to {text!r}; drop topic=")
        return CaptureLive(text)
    return RecordingLive(text, realtime=realtime, topic=topic, loop=loop)


__all__ = ["CaptureLive", "DtpsLive", "LiveFrames", "LiveSource", "LiveStatus", "RecordingLive", "RosLive", "is_live_spec",
           "master_uri", "open_live", "ros_python", "run_ros_helper"]
