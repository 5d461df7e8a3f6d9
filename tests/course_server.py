"""A running ``dtscal course`` server, checked as a student sees it (shared by test_course_command and
test_handout: a helper module, not a test file)."""

import json
import os
import signal
import socket
import subprocess
import time
import urllib.error
import urllib.request


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def check_student_view(proc, port: int, patience: float = 90.0) -> list[str]:
    """The server answers, its printed URL opens notebook 01, and no solution is in its file tree; returns the lines
    the command printed up to the address."""
    token, url = None, None
    deadline = time.time() + patience
    lines = []
    while time.time() < deadline and token is None:
        line = proc.stdout.readline().decode(errors="replace")
        if not line and proc.poll() is not None:
            break
        lines.append(line)
        if "token=" in line and "http" in line:
            url = line[line.index("http"):].split()[0].strip()
            token = url.split("token=")[1]
    assert token, "JupyterLab did not start:\n" + "".join(lines[-30:])
    assert "/lab/tree/01_pinhole_projection.ipynb?" in url, url
    listing = json.loads(_get(f"http://127.0.0.1:{port}/api/contents?token={token}"))
    names = {item["name"] for item in listing["content"]}
    assert "01_pinhole_projection.ipynb" in names and "solutions" not in names, names
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/lab/tree/01_pinhole_projection.ipynb?token={token}",
                                timeout=30) as r:
        assert r.status == 200 and b"JupyterLab" in r.read()
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/contents/01_pinhole_projection.ipynb?token={token}",
                                timeout=30) as r:
        assert r.status == 200
    return lines


def _get(url: str, patience: float = 30.0) -> bytes:
    """GET with retries while the server finishes binding its socket."""
    deadline = time.time() + patience
    while True:
        try:
            with urllib.request.urlopen(url, timeout=30) as r:
                return r.read()
        except urllib.error.URLError as exc:
            if not isinstance(exc.reason, ConnectionRefusedError) or time.time() > deadline:
                raise
            time.sleep(0.2)


def _stop(proc):
    try:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(timeout=20)
    except ProcessLookupError:
        pass  # already gone
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=20)
