"""Reaching a robot over DTPS, Duckietown's pub-sub over HTTP, the way ``duckietown-sdk`` does.

A robot (a Duckiebot on ``ente`` or a DD24-B) runs a *switchboard* on ``<ROBOT>.local:11911``; its camera
driver publishes each frame there as a ``duckietown_messages`` ``CompressedImage`` on
``<ROBOT>/sensor/camera/<SENSOR>/jpeg`` and the calibration it uses as a ``CameraIntrinsicCalibration`` on
``.../parameters``. The robot's key-value store (``dt-kvstore``, port 11411) serves each calibration file
``/data/config/calibrations/<kind>/<ROBOT>.yaml`` as the read-write queue ``data/calibration/<kind>/current``:
what is published there is written to that file, and the camera driver, which subscribes to it, takes the
new intrinsics at once. Names and sources: :mod:`dtscal_lib.duckietown`.

The client is PyPI's ``dtps-http`` (module ``dtps``) with ``duckietown-messages``, both installed with the kit.

A spec names the robot: ``dtps:ROBOT`` (its camera ``front_center`` at ``ROBOT.local:11911``),
``dtps:ROBOT/SENSOR`` (another camera), ``dtps:ROBOT@HOST`` or ``dtps:ROBOT@HOST:PORT`` (an address instead
of ``ROBOT.local``: a robot without mDNS, the simulator at ``127.0.0.1:7501``, a test server).
"""

from __future__ import annotations

import asyncio
import logging
import os
import re
import threading
from dataclasses import dataclass

from . import duckietown as dt
from .errors import SourceError

__all__ = ["DtpsRobot", "import_dtps", "parse_dtps_spec", "run_async"]

_SPEC = re.compile(r"^(?P<robot>[A-Za-z0-9_]+)(?:/(?P<sensor>[A-Za-z0-9_-]+))?"
                   r"(?:@(?P<host>[A-Za-z0-9_.\-]+|\[[0-9a-fA-F:]+\])(?::(?P<port>\d{1,5}))?)?$")


@dataclass(frozen=True)
class DtpsRobot:
    """Where a robot's switchboard and key-value store are, and which camera to read."""

    robot: str
    host: str
    port: int = dt.DTPS_SWITCHBOARD_PORT
    sensor: str = dt.DTPS_CAMERA_SENSOR
    #: the key-value store's URL (default the robot's host on :data:`~dtscal_lib.duckietown.KVSTORE_PORT`)
    kvstore: str | None = None

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}/"

    @property
    def kvstore_url(self) -> str:
        """``kvstore``, else ``$DTSCAL_DTPS_KVSTORE`` (a test robot, a simulator), else ``http://HOST:11411/``."""
        return self.kvstore or os.environ.get("DTSCAL_DTPS_KVSTORE") or f"http://{self.host}:{dt.KVSTORE_PORT}/"

    @property
    def camera(self) -> tuple[str, ...]:
        return dt.dtps_camera_path(self.robot, self.sensor)

    @property
    def topic(self) -> str:
        """The camera's JPEG queue, ``ROBOT/sensor/camera/SENSOR/jpeg``."""
        return "/".join((*self.camera, dt.DTPS_CAMERA_JPEG))

    def with_kvstore(self, url: str | None) -> DtpsRobot:
        if not url:
            return self
        if not re.match(r"^https?://[^/]+/?$", url):
            raise SourceError(f"kvstore {url!r} must look like http://HOST:PORT/ (the robot's is "
                              f"http://ROBOT.local:{dt.KVSTORE_PORT}/)")
        return DtpsRobot(self.robot, self.host, self.port, self.sensor, url.rstrip("/") + "/")


def parse_dtps_spec(text: str, kvstore: str | None = None) -> DtpsRobot:
    """``ROBOT[/SENSOR][@HOST[:PORT]]`` (the part after ``dtps:``) as a :class:`DtpsRobot`."""
    m = _SPEC.match(text.strip())
    if not m:
        raise SourceError(f"dtps:{text!r}: write dtps:ROBOT (e.g. dtps:autobot01), dtps:ROBOT/SENSOR or "
                          "dtps:ROBOT@HOST:PORT; a robot name has letters, digits and '_' only")
    robot, port = m["robot"], int(m["port"] or dt.DTPS_SWITCHBOARD_PORT)
    if not 0 < port < 65536:
        raise SourceError(f"dtps:{text!r}: port {port} is not a TCP port")
    host = (m["host"] or dt.DTPS_HOST.format(robot=robot)).strip("[]")
    return DtpsRobot(robot, host, port, m["sensor"] or dt.DTPS_CAMERA_SENSOR).with_kvstore(kvstore)


def import_dtps():
    """``(dtps, CompressedImage, CameraIntrinsicCalibration)``; a :class:`SourceError` saying what to install."""
    try:
        import dtps
        from duckietown_messages.calibrations.camera_intrinsic import CameraIntrinsicCalibration
        from duckietown_messages.sensors.compressed_image import CompressedImage
    except ImportError as exc:
        raise SourceError(f"DTPS needs PyPI's dtps-http and duckietown-messages ({exc}); they come with the kit: "
                          "pip install -e . (or pip install dtps-http duckietown-messages)") from None
    # dtps logs every connection attempt at DEBUG/INFO on its own handlers: the kit says what matters itself
    for name in ("dtps", "dtps_http", "dtps_http.client", "aiohttp"):
        logging.getLogger(name).setLevel(logging.CRITICAL)
    return dtps, CompressedImage, CameraIntrinsicCalibration


def run_async(coro, timeout: float):
    """Run ``coro`` to its end on a fresh event loop in a thread of its own (a notebook's loop is busy).

    Raises :class:`TimeoutError` after ``timeout`` seconds, or what the coroutine raised.
    """
    box: dict = {}

    def main():
        try:
            box["value"] = asyncio.run(asyncio.wait_for(coro, timeout))
        except BaseException as exc:  # noqa: BLE001 (handed to the caller's thread)
            box["error"] = exc

    t = threading.Thread(target=main, daemon=True, name="dtscal-dtps-call")
    t.start()
    t.join(timeout + 10.0)
    if t.is_alive():
        raise TimeoutError(f"no answer within {timeout:g} s")
    if "error" in box:
        raise box["error"]
    return box.get("value")
