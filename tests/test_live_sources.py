"""Live sources without ROS: a recording played as a camera, a webcam that is unplugged, corrupt
frames; the extrinsic file formats; the extrinsic upload to a robot's file server (a real HTTP
server on loopback)."""

from __future__ import annotations

import hashlib
import http.server
import os
import queue
import threading
import time

import cv2
import numpy as np
import pytest
import yaml

from dtscal_lib import calib_files, datasets
from dtscal_lib import duckietown as dt
from dtscal_lib.cli import main as cli_main
from dtscal_lib.errors import CalibrationFileError, SourceError
from dtscal_lib.robot import CommitError, commit_extrinsics, robot_files_url
from dtscal_lib.sources import open_live
from dtscal_lib.sources.live import CaptureLive, LiveFrames, LiveSource, is_live_spec
from live_fakes import jpeg_frame, write_test_bag



@pytest.fixture(scope="module")
def session():
    return datasets.session_dir()


class _FakeTime:
    """Stands in for the ``time`` module inside ``sources.live``: ``monotonic()`` moves only when the
    player waits (through :class:`_FakeStop`), so its pacing is seen without any real waiting."""

    def __init__(self):
        self.now = 500.0

    def monotonic(self) -> float:
        return self.now

    def __getattr__(self, name):  # time.time() for the arrival stamps stays the real one
        return getattr(time, name)


class _FakeStop:
    """The player's stop event: never set; ``wait(s)`` moves the fake clock by ``s`` at once."""

    def __init__(self, clock: _FakeTime):
        self.clock, self.waits = clock, []

    def is_set(self) -> bool:
        return False

    def wait(self, seconds: float) -> bool:
        self.waits.append(seconds)
        self.clock.now += seconds
        return False


def test_recording_plays_at_its_recorded_rate(tmp_path, monkeypatch):
    """Each frame is handed out when its stamp comes due on the player's clock: frame i of a 30 fps
    recording at i/30 s, never the whole bag at once (a fake clock: no real waiting, no rate measured)."""
    from dtscal_lib.sources import live

    clock = _FakeTime()
    monkeypatch.setattr(live, "time", clock)
    bag = write_test_bag(tmp_path / "r.bag", 60, fps=30)
    cam = open_live(bag)  # not started: the test runs the player's loop itself, in this thread
    pushed = []
    real_push = cam._push
    monkeypatch.setattr(cam, "_push", lambda *a, **k: (pushed.append(clock.now), real_push(*a, **k)))
    stop = _FakeStop(clock)
    cam._run(stop)
    assert len(pushed) == 60 and cam.status.frames == 60 and cam.status.state == "ended"
    assert np.allclose(np.array(pushed) - pushed[0], np.arange(60) / 30, atol=1e-6), pushed[:5]
    assert len(stop.waits) == 59 and np.allclose(stop.waits, 1 / 30, atol=1e-6)
    assert cam.latest(timeout=0).index == 59


def test_recording_played_as_fast_as_it_decodes_never_waits(tmp_path, monkeypatch):
    from dtscal_lib.sources import live

    clock = _FakeTime()
    monkeypatch.setattr(live, "time", clock)
    cam = open_live(write_test_bag(tmp_path / "r.bag", 20, fps=30), realtime=False)
    stop = _FakeStop(clock)
    cam._run(stop)
    assert stop.waits == [] and cam.status.frames == 20


class _ManualCamera(LiveSource):
    """A camera the test drives frame by frame: ``feed(n)`` delivers n frames, ``end()`` ends it."""

    kind = "manual"

    def __init__(self):
        super().__init__("manual camera")
        self._feed: queue.Queue = queue.Queue()

    def feed(self, n: int) -> None:
        want = self.status.frames + n
        for _ in range(n):
            self._feed.put(np.zeros((4, 4, 3), np.uint8))
        deadline = time.monotonic() + 60  # a safety net only: the receiver takes microseconds per frame
        while self.status.frames < want and time.monotonic() < deadline:
            time.sleep(0.005)
        assert self.status.frames == want, self.status

    def end(self) -> None:
        self._feed.put(None)

    def _run(self, stop) -> None:
        while not stop.is_set():
            image = self._feed.get()
            if image is None:
                break
            self._push(image, float(self.status.frames), f"manual#{self.status.frames}")
        self._set_state("ended", "the manual camera ended; press Reconnect")

    def _halt(self) -> None:
        self._feed.put(None)


def test_slow_consumer_gets_the_newest_frame_never_a_backlog():
    """A consumer that comes back after many frames gets the newest one, never the next in a queue."""
    with _ManualCamera() as cam:
        cam.feed(5)
        f = cam.latest(after=-1, timeout=0)
        assert f.index == 4  # not 0: the four older frames were never queued
        cam.feed(7)
        g = cam.latest(after=f.index, timeout=0)
        assert g.index == 11  # the newest, 7 frames later; 5..10 were skipped
        assert cam.latest(after=g.index, timeout=0) is None  # nothing newer: no frame handed out twice
        cam.feed(1)
        assert cam.latest(after=g.index, timeout=0).index == 12
        cam.end()
        assert cam.latest(after=12, timeout=5) is None  # ended: nothing newer
        assert cam.status.state == "ended" and cam.status.frames == 13
        assert cam.latest(timeout=0).index == 12  # the last frame stays readable


def test_recording_end_keeps_last_frame_and_reconnect_replays(tmp_path):
    bag = write_test_bag(tmp_path / "r.bag", 20)
    cam = open_live(bag, realtime=False).start()
    try:
        deadline = time.monotonic() + 10
        while cam.status.state != "ended" and time.monotonic() < deadline:
            time.sleep(0.02)
        st = cam.status
        assert st.state == "ended" and st.frames == 20
        assert "ended after 20 frames" in st.message and "Reconnect" in st.message
        last = cam.latest(timeout=0)
        assert last is not None and last.index == 19  # the last frame stays readable
        waited = []
        cam._cond.wait = lambda *a: waited.append(a)  # an ended source must not wait for a frame at all
        assert cam.latest(after=last.index, timeout=5) is None
        assert waited == []  # it answered at once, without waiting on the receiver
        del cam._cond.wait
        cam.reconnect()
        again = cam.latest(after=last.index, timeout=5)
        assert again is not None and again.index > last.index  # indices keep growing across reconnects
    finally:
        cam.close()
    assert cam.status.state == "ended"
    with pytest.raises(SourceError, match="closed"):
        cam.start()


def test_loop_repeats_the_recording(tmp_path):
    bag = write_test_bag(tmp_path / "r.bag", 5, fps=100)
    with open_live(bag, loop=True) as cam:
        deadline = time.monotonic() + 10
        while cam.status.frames < 12 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert cam.status.frames >= 12 and cam.status.state == "running"


def test_corrupt_frames_are_counted_never_handed_out(tmp_path):
    bag = write_test_bag(tmp_path / "r.bag", 30, corrupt={3, 4, 17})
    seen = []
    with open_live(bag, realtime=False) as cam:
        after = -1
        while (f := cam.latest(after=after, timeout=2)) is not None:
            assert f.ok and f.image is not None
            seen.append(f)
            after = f.index
        st = cam.status
    assert st.state == "ended" and st.frames == 30
    assert st.bad == {"corrupt_jpeg": 3}


def test_bad_specs_say_what_to_do(tmp_path):
    with pytest.raises(SourceError, match="does not exist"):
        open_live(str(tmp_path / "nope.bag"))
    with pytest.raises(SourceError, match="device:N"):
        open_live("device:front")
    with pytest.raises(SourceError, match="topic="):
        open_live("device:0", topic="/x")
    with pytest.raises(SourceError, match="robot name"):
        open_live("ros:bad name")
    assert is_live_spec("ros:autobot01") and is_live_spec("rtsp://cam/1") and not is_live_spec("a.bag")


class _FakeCamera:
    """Stands in for cv2.VideoCapture of a webcam: ``frames`` good reads, then nothing (unplugged)."""

    def __init__(self, frames: int):
        self.left = frames
        self.released = False

    def isOpened(self):
        return True

    def read(self):
        if self.left <= 0 or self.released:
            return False, None
        self.left -= 1
        return True, np.full((48, 64, 3), self.left, np.uint8)

    def release(self):
        self.released = True


def test_unplugged_webcam_reports_error_keeps_frame_and_reconnects(monkeypatch):
    opened = []

    def fake_open(self):
        opened.append(_FakeCamera(10))
        return opened[-1]

    monkeypatch.setattr(CaptureLive, "_open", fake_open)
    monkeypatch.setattr("dtscal_lib.sources.live.STALL_SECONDS", 0.3)
    cam = open_live("device:0").start()
    try:
        deadline = time.monotonic() + 10
        while cam.status.state != "error" and time.monotonic() < deadline:
            time.sleep(0.05)
        st = cam.status
        assert st.state == "error" and "unplugged" in st.message and "Reconnect" in st.message
        assert st.frames == 10 and opened[0].released
        last = cam.latest(timeout=0)
        assert last is not None and last.index == 9
        cam.reconnect()
        f = cam.latest(after=9, timeout=5)
        assert f is not None and f.index >= 10 and len(opened) == 2
    finally:
        cam.close()


def test_unopenable_camera_is_an_error_status(monkeypatch):
    class Closed(_FakeCamera):
        def isOpened(self):
            return False

    monkeypatch.setattr(CaptureLive, "_open", lambda self: Closed(0))
    with open_live("device:3") as cam:
        assert cam.latest(timeout=3) is None
        assert cam.status.state == "error" and "could not open camera 3" in cam.status.message


def test_live_frames_stop_when_done(tmp_path):
    bag = write_test_bag(tmp_path / "r.bag", 200, fps=200)
    seen = []
    frames = LiveFrames(bag, done=lambda: len(seen) >= 5)
    for f in frames:
        seen.append(f.index)
    assert len(seen) == 5 and frames.stopped == "stopped: enough samples"


# ---------------------------------------------------------------------- extrinsic file formats
def _calib(session):
    return calib_files.IntrinsicCalibration.from_dict(dt.DEFAULT_INTRINSICS, "default")


def test_v2_roundtrip_and_duckietown_composition(tmp_path, session):
    calib = _calib(session)
    H = np.asarray(dt.DEFAULT_HOMOGRAPHY, float).reshape(3, 3)
    path = calib_files.save_extrinsics_as(H, tmp_path, "bot1", fmt="2", intrinsics=calib)
    text = path.read_text()
    assert text.startswith("# IMPORTANT")
    doc = yaml.safe_load(text)
    assert doc["version"] == "2" and isinstance(doc["date"], str)
    F = np.array(doc["homography"])
    assert F.shape == (3, 3)
    # lib-dt-computer-vision reads it as Hv2i @ F: normalized image vector -> ground
    Kp = calib.P[:, :3]
    fx, fy, cx, cy = Kp[0, 0], Kp[1, 1], Kp[0, 2], Kp[1, 2]
    tl = np.array([-cx / fx, -cy / fy])
    br = np.array([(calib.width - 1 - cx) / fx, (calib.height - 1 - cy) / fy])
    s = 1 / (br - tl)
    Hv2i = np.array([[s[0], 0, -tl[0] * s[0]], [0, s[1], -tl[1] * s[1]], [0, 0, 1]])
    Hv = Hv2i @ F
    for u, v in [(320, 479), (100, 300), (600, 420)]:
        g_classic = H @ [u, v, 1]
        g_v2 = Hv @ [(u - cx) / fx, (v - cy) / fy, 1]
        np.testing.assert_allclose(g_v2[:2] / g_v2[2], g_classic[:2] / g_classic[2], atol=1e-9)
    back, fmt, date = calib_files.read_extrinsic_file(path, calib)
    assert fmt == "2" and date == doc["date"]
    np.testing.assert_allclose(back, H / H[2, 2], rtol=1e-9, atol=1e-12)
    with pytest.raises(CalibrationFileError, match="intrinsic file"):
        calib_files.read_extrinsic_file(path)
    classic = calib_files.save_extrinsics_as(back, tmp_path, "bot2")
    H2, fmt2, _ = calib_files.read_extrinsic_file(classic)
    assert fmt2 == "classic" and np.allclose(H2, back)


def test_bad_v2_files_are_refused(tmp_path, session):
    calib = _calib(session)
    p = tmp_path / "x.yaml"
    p.write_text("version: '3'\nhomography: [[1,0,0],[0,1,0],[0,0,1]]\n")
    with pytest.raises(CalibrationFileError, match="version"):
        calib_files.read_extrinsic_file(p, calib)
    p.write_text("version: '2'\nhomography: [1, 2, 3]\n")
    with pytest.raises(CalibrationFileError, match="3 rows of 3"):
        calib_files.read_extrinsic_file(p, calib)
    with pytest.raises(CalibrationFileError, match="unknown"):
        calib_files.save_extrinsics_as(np.eye(3), tmp_path, "b", fmt="v3")


def test_cli_extrinsics_writes_version_2(tmp_path, session, capsys):
    intr = tmp_path / "cal"
    assert cli_main(["calibrate-intrinsics", "--source", str(session / "intrinsics.bag"), "--out", str(intr),
                     "-q"]) == 0
    intr_file = intr / "camera_intrinsic" / "synthbot.yaml"
    out = tmp_path / "out"
    assert cli_main(["calibrate-extrinsics", "--source", str(session / "extrinsics.bag"), "--intrinsics",
                     str(intr_file), "--out", str(out), "--format", "2", "-q"]) == 0
    f = out / "camera_extrinsic" / "synthbot.yaml"
    H, fmt, _ = calib_files.read_extrinsic_file(f, intr_file)
    assert fmt == "2"
    assert cli_main(["calibrate-extrinsics", "--source", str(session / "extrinsics.bag"), "--intrinsics",
                     str(intr_file), "--out", str(tmp_path / "c"), "-q"]) == 0
    Hc = calib_files.load_extrinsics(tmp_path / "c" / "camera_extrinsic" / "synthbot.yaml")
    np.testing.assert_allclose(H, Hc / Hc[2, 2], rtol=1e-6)


# ---------------------------------------------------------------------- extrinsic upload
def test_commit_extrinsics_uploads_the_file(tmp_path, file_server):
    base, stored = file_server
    path = calib_files.save_extrinsics(np.asarray(dt.DEFAULT_HOMOGRAPHY).reshape(3, 3), tmp_path, "bot1")
    url = base + "/files/data/config/calibrations/camera_extrinsic/bot1.yaml"
    msg = commit_extrinsics("bot1", path, url=url)
    assert "uploaded" in msg and url in msg
    assert stored["/files/data/config/calibrations/camera_extrinsic/bot1.yaml"] == path.read_bytes()
    assert robot_files_url("bot1") == "http://bot1.local/files/data/config/calibrations/camera_extrinsic/bot1.yaml"
    assert robot_files_url("bot1", "http://10.0.0.7:11311").startswith("http://10.0.0.7/files/")


def test_commit_extrinsics_without_server_keeps_the_file(tmp_path):
    path = calib_files.save_extrinsics(np.asarray(dt.DEFAULT_HOMOGRAPHY).reshape(3, 3), tmp_path, "bot1")
    before = hashlib.sha256(path.read_bytes()).hexdigest()
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # nothing listens here once the socket is closed
    with pytest.raises(CommitError, match="cannot reach the robot's file server") as e:
        commit_extrinsics("bot1", path, url=f"http://127.0.0.1:{port}/files/x.yaml", timeout=3)
    assert "scp" in str(e.value) and "is kept" in str(e.value)
    assert hashlib.sha256(path.read_bytes()).hexdigest() == before
    bad = tmp_path / "bad.yaml"
    bad.write_text("nothing: here\n")
    with pytest.raises(CommitError, match="not an extrinsic file"):
        commit_extrinsics("bot1", bad, url="http://127.0.0.1:9/x")


# ---------------------------------------------------------------------- a real MJPEG stream over HTTP
class _Mjpeg(http.server.BaseHTTPRequestHandler):
    """An IP camera's MJPEG stream: ``frames`` JPEGs as multipart/x-mixed-replace, then the stream ends."""

    frames = 30

    def do_GET(self):
        self.send_response(200)
        self.send_header("Content-Type", "multipart/x-mixed-replace; boundary=frame")
        self.end_headers()
        try:
            for i in range(self.frames):
                b = jpeg_frame(i)
                self.wfile.write(b"--frame\r\nContent-Type: image/jpeg\r\nContent-Length: %d\r\n\r\n" % len(b))
                self.wfile.write(b + b"\r\n")
                time.sleep(1 / 30)
        except (BrokenPipeError, ConnectionResetError):
            pass

    def log_message(self, *args):
        pass


def test_mjpeg_stream_url_ends_and_reconnects():
    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Mjpeg)
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    url = f"http://127.0.0.1:{srv.server_address[1]}/video.mjpg"
    try:
        with open_live(url) as cam:
            first = cam.latest(timeout=15)
            assert first is not None and first.image.shape == (120, 160, 3), cam.status
            deadline = time.monotonic() + 20
            while cam.status.state != "ended" and time.monotonic() < deadline:
                time.sleep(0.05)
            st = cam.status
            assert st.state == "ended" and "Reconnect" in st.message and url in st.message
            assert 20 <= st.frames <= 30, st
            last = cam.latest(timeout=0)
            assert last is not None
            cam.reconnect()
            again = cam.latest(after=last.index, timeout=15)
            assert again is not None and again.index > last.index
    finally:
        srv.shutdown()
        srv.server_close()


def test_offline_commit_to_a_folder_that_cannot_be_written(tmp_path):
    """Writing camera_intrinsic/<ROBOT>.yaml fails: a clear error, the previous file intact, saving elsewhere works."""
    calib = calib_files.IntrinsicCalibration.from_dict(dt.DEFAULT_INTRINSICS, "default")
    folder = tmp_path / "calibrations"
    previous = calib_files.save_intrinsics(calib, folder, "bot1")
    before = previous.read_bytes()
    target = folder / "camera_intrinsic"
    if os.geteuid() == 0:
        # root ignores permission bits: make the file's place unusable instead (a file where the folder is)
        blocked = tmp_path / "blocked"
        blocked.write_text("not a folder")
        with pytest.raises(CalibrationFileError, match="could not be written"):
            calib_files.save_intrinsics(calib, blocked, "bot2")
    target.chmod(0o555)
    try:
        if os.geteuid() != 0:
            with pytest.raises(CalibrationFileError, match="could not be written.*previous file is unchanged"):
                calib_files.save_intrinsics(calib, folder, "bot1")
    finally:
        target.chmod(0o755)
    assert previous.read_bytes() == before
    assert calib_files.save_intrinsics(calib, tmp_path / "elsewhere", "bot1").exists()


def _rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


@pytest.mark.slow
def test_memory_stays_flat_over_18000_frames(tmp_path):
    """Ten minutes of a 30 fps camera, played as fast as possible: no queue, no image history.

    Keeping the 18,000 frames (57.6 kB each here) would take about 1 GB; the resident size may
    grow by 30 MB at most (allocator noise).
    """
    bag = write_test_bag(tmp_path / "r.bag", 50)
    with open_live(bag, realtime=False, loop=True) as cam:
        after, early = -1, None
        while cam.status.frames < 18_000:
            f = cam.latest(after=after, timeout=5)
            assert f is not None, cam.status
            after = f.index
            if early is None and cam.status.frames >= 2_000:
                early = _rss_bytes()
        late = _rss_bytes()
        assert cam.status.state == "running" and cam.status.bad == {}
    assert late - early < 30_000_000, (early, late)


@pytest.mark.slow
def test_cli_calibrates_from_a_webcam(monkeypatch, tmp_path, capsys):
    """``--source device:0`` end to end; the webcam is stood in for by the recording's frames.

    The stand-in delivers the recording's frames in order, each once, and waits (a safety net of
    60 s) until the kit has taken the previous one before it delivers the next: the run sees every
    frame however slow or loaded the machine is (a real-time stand-in dropped more frames on a busy
    machine, so the number of samples depended on the load).
    """
    frames = [data for _, _, data in datasets.read_bag_jpegs(datasets.session_dir() / "intrinsics.bag")]
    taken = threading.Event()
    taken.set()
    real_latest = CaptureLive.latest

    def latest(self, *a, **k):
        f = real_latest(self, *a, **k)
        if f is not None:
            taken.set()
        return f

    monkeypatch.setattr(CaptureLive, "latest", latest)

    class RecordedCamera(_FakeCamera):
        def __init__(self):
            super().__init__(len(frames))
            self.i = 0

        def read(self):
            if self.i >= len(frames):
                return False, None
            taken.wait(60)  # the kit took the previous frame
            taken.clear()
            self.i += 1
            return True, cv2.imdecode(np.frombuffer(frames[self.i - 1], np.uint8), cv2.IMREAD_COLOR)

    monkeypatch.setattr(CaptureLive, "_open", lambda self: RecordedCamera())
    out = tmp_path / "cal"
    code = cli_main(["calibrate-intrinsics", "--source", "device:0", "--robot", "laptopcam", "--out", str(out),
                     "--max-seconds", "600", "--json", "-q"])  # 600 s: a safety net
    assert code == 0
    import json

    run = json.loads(capsys.readouterr().out)
    assert run["samples_used"] >= 15 and run["output"].endswith("camera_intrinsic/laptopcam.yaml")
    K = calib_files.load_intrinsics(out / "camera_intrinsic" / "laptopcam.yaml").K
    truth = np.asarray(datasets.load_truth()["camera"]["K"])
    assert abs(K[0, 0] / truth[0, 0] - 1) < 0.01 and abs(K[1, 1] / truth[1, 1] - 1) < 0.01
