"""Stand-ins for the live-source tests: small JPEG frames, a recording of them, a robot's file server.

Shared by test_live_sources and test_ros_live (a helper module; the fixture ``file_server`` is registered
in conftest.py).
"""

from __future__ import annotations

import http.server
import threading

import cv2
import numpy as np
import pytest

from dtscal_lib.sources import write_compressed_image_bag

TOPIC = "/testbot/camera_node/image/compressed"


def jpeg_frame(i: int) -> bytes:
    img = np.full((120, 160, 3), (10 * i % 255, 90, 160), np.uint8)
    cv2.putText(img, str(i), (40, 80), cv2.FONT_HERSHEY_SIMPLEX, 1.5, (255, 255, 255), 3)
    return cv2.imencode(".jpg", img)[1].tobytes()


def write_test_bag(path, n: int, fps: float = 30.0, corrupt=()) -> str:
    frames = []
    for i in range(n):
        data = jpeg_frame(i)
        if i in corrupt:
            data = data[: len(data) // 2]  # cut short, as a dropped transfer
        frames.append((int(1_700_000_000e9 + i * 1e9 / fps), data))
    return str(write_compressed_image_bag(path, TOPIC, frames))


class _FileServer(http.server.BaseHTTPRequestHandler):
    stored: dict = {}  # noqa: RUF012 (one server per test; reset by the fixture)

    def do_POST(self):
        body = self.rfile.read(int(self.headers["Content-Length"]))
        type(self).stored[self.path] = body
        self.send_response(200)
        self.end_headers()
        self.wfile.write(b"ok")

    def log_message(self, *args):
        pass


@pytest.fixture
def file_server():
    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _FileServer)
    _FileServer.stored = {}
    t = threading.Thread(target=srv.serve_forever, daemon=True)
    t.start()
    try:
        yield f"http://127.0.0.1:{srv.server_address[1]}", _FileServer.stored
    finally:
        srv.shutdown()
        srv.server_close()
