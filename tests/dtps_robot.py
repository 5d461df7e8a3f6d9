"""A robot on loopback the way today's Duckietown robots are reached: dtps-http's own server, real messages.

:class:`DtpsRobotServer` starts ``dtps-http``'s server (``dtps.context(..., urls=["create:http://127.0.0.1:PORT/"])``)
in a thread and, like a Duckiebot's camera driver (dt-duckiebot-interface ``camera_driver_abs.py``), publishes
on ``ROBOT/sensor/camera/front_center/``: ``jpeg`` (``duckietown_messages`` ``CompressedImage``), ``parameters``
(``CameraIntrinsicCalibration``) and ``info`` (``Camera``); like its key-value store (dt-kvstore) it serves
``data/calibration/camera_intrinsic/current`` and ``.../camera_extrinsic/current``, which accept what is
published (``refuse=True``: answer HTTP 403, as a read-only queue does; ``keep_other=True``: take the value
but keep something else, as a store that drops what it cannot parse would). The paths are spelled here as
Duckietown's code spells them, not taken from the kit: a wrong path in the kit is a robot the kit cannot find.

Frames: the bundled recording's JPEGs at ``fps``; ``mode="png"`` sends them as ``format: png`` messages,
``mode="garbage"`` as ``jpeg`` messages whose bytes are not a JPEG. :meth:`go_away` closes the server
mid-stream. :func:`silent_port` is a port that accepts connections and never answers (a robot that hangs).

A helper module (see conftest.py), no tests of its own.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import socket
import threading
import time

from dtscal_lib import datasets
from dtscal_lib import duckietown as dt

#: Duckietown's paths, as dt-duckiebot-interface (``camera_driver_abs.py``: ``switchboard / "sensor" / "camera" /
#: sensor_name``) and dt-kvstore (``data/calibration/{key}/current``) create them
CAMERA = ("{robot}", "sensor", "camera", "front_center")
KVSTORE_KEY = ("data", "calibration", "{kind}", "current")


@functools.cache
def recording(bag: str) -> list[bytes]:
    """The JPEGs of a bundled bag (read once per test process)."""
    return [data for _, _, data in datasets.read_bag_jpegs(datasets.session_dir() / bag)]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def silent_port():
    """A loopback port whose listener accepts TCP connections and never answers them."""
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(64)
    try:
        yield s.getsockname()[1]
    finally:
        s.close()


class DtpsRobotServer:
    """A robot's switchboard and key-value store on one dtps-http server (see module doc)."""

    def __init__(self, robot: str = "testbot", *, fps: float = 30.0, mode: str = "jpeg", refuse: bool = False,
                 keep_other: bool = False,
                 bag: str = "intrinsics.bag", step: int = 1, loop: bool = True, size=(640, 480)):
        self.robot, self.fps, self.mode, self.refuse, self.loop_frames = robot, fps, mode, refuse, loop
        self.keep_other = keep_other
        self.size = size
        self.jpegs = recording(bag)[::step]
        self.port = free_port()
        self.sent = 0
        self.stored: dict = {}
        self._loop: asyncio.AbstractEventLoop | None = None
        self._ready = threading.Event()
        self._stop: asyncio.Event | None = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._main, daemon=True, name="dtps-robot")

    @property
    def spec(self) -> str:
        return f"dtps:{self.robot}@127.0.0.1:{self.port}"

    @property
    def kvstore(self) -> str:
        return f"http://127.0.0.1:{self.port}/"

    def __enter__(self) -> DtpsRobotServer:
        self._thread.start()
        if not self._ready.wait(30):
            raise RuntimeError("the DTPS test robot did not start within 30 s")
        if self._error is not None:
            raise self._error
        return self

    def __exit__(self, *exc) -> None:
        self.go_away()

    def go_away(self) -> None:
        """Close the server (the robot switched off); the kit's subscription sees the robot vanish."""
        if self._stop is not None and self._thread.is_alive():
            with contextlib.suppress(RuntimeError):  # its loop has ended already
                self._loop.call_soon_threadsafe(self._stop.set)
            self._thread.join(30)

    def _main(self) -> None:
        try:  # asyncio.run ends every task of the server before closing the loop (no stray coroutine warnings)
            asyncio.run(self._serve())
        except BaseException as exc:  # noqa: BLE001 (handed to the test)
            self._error = exc
            self._ready.set()

    async def _serve(self) -> None:
        import dtps
        from duckietown_messages.calibrations.camera_intrinsic import CameraIntrinsicCalibration
        from duckietown_messages.sensors.camera import Camera
        from duckietown_messages.sensors.compressed_image import CompressedImage
        from duckietown_messages.standard.header import Header

        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        srv = await dtps.context(f"robot-{self.port}", urls=[f"create:http://127.0.0.1:{self.port}/"])
        camera = srv.navigate(*(c.format(robot=self.robot) for c in CAMERA))
        jpeg = await (camera / "jpeg").queue_create()
        parameters = await (camera / "parameters").queue_create()
        info = await (camera / "info").queue_create()
        await parameters.publish(CameraIntrinsicCalibration(
            K=dt.default_K().ravel().tolist(), D=dt.default_dist().tolist(), P=dt.default_P().ravel().tolist(),
            R=[1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0]).to_rawdata())
        await info.publish(Camera(header=Header(), name=CAMERA[-1], type="camera", simulated=False,
                                  description="RGB8/JPEG Camera", frame_id="", frequency=self.fps, maker="test",
                                  model="test", width=self.size[0], height=self.size[1], fov=2.8).to_rawdata())

        async def refuse(_otc):
            return dtps.TransformError(403, "read-only: this robot does not take calibrations")

        async def other(_otc):
            return dtps.RawData.cbor_from_native_object({"image_width": 1})

        transform = refuse if self.refuse else other if self.keep_other else None
        for kind in ("camera_intrinsic", "camera_extrinsic"):
            path = tuple(c.format(kind=kind) for c in KVSTORE_KEY)
            queue = await (srv.navigate(*path)).queue_create(**({"transform": transform} if transform else {}))

            async def keep(rd, kind=kind):
                self.stored[kind] = rd.get_as_native_object()

            await queue.subscribe(keep)
        self._ready.set()
        period = 1.0 / self.fps
        t0 = time.monotonic()
        i = 0
        while not self._stop.is_set():
            if i >= len(self.jpegs) and not self.loop_frames:
                await asyncio.sleep(0.05)
                continue
            data = self.jpegs[i % len(self.jpegs)]
            fmt = "png" if self.mode == "png" else "jpeg"
            if self.mode == "garbage":
                data = b"GIF89a" + data[6:200]
            await jpeg.publish(CompressedImage(header=Header(), format=fmt, data=data).to_rawdata())
            self.sent += 1
            i += 1
            wait = t0 + i * period - time.monotonic()
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(self._stop.wait(), max(wait, 0.0))
        await srv.aclose()
