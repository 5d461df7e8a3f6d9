"""The live intrinsic calibrator driven headless: its buttons clicked from Python, on the real recording.

Faults: the source ends mid-session (the UI says so, keeps every sample, RECONNECT works), corrupt
frames are counted and never shown as a traceback, COMMIT fails (no ROS master, a folder that
cannot be written), CALIBRATE on degenerate samples.
"""

from __future__ import annotations

import os
import socket
import time
import zipfile

import cv2
import numpy as np
import pytest

from dtscal_lib import calib_files, datasets
from dtscal_lib.sources import open_source, write_compressed_image_bag
from dtscal_lib.ui import LiveCalibrator
from dtscal_lib.ui.archive import load_session

SESSION = datasets.session_dir()
BAG = SESSION / "intrinsics.bag"


def wait_for(cond, timeout=60.0, step=0.05):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(step)
    return cond()


@pytest.fixture(scope="module")
def truth():
    return datasets.load_truth()


@pytest.fixture(scope="module")
def filled():
    """A calibrator that has seen every frame of the recording (stepped, no thread: deterministic)."""
    app = LiveCalibrator(str(BAG), autostart=False)
    for f in open_source(BAG):
        if f.ok:
            app.loop.step(f)
    yield app
    app.close()


def test_bars_fill_and_calibrate_is_enabled_by_the_ros_rule(filled):
    assert filled.robot == "synthbot"
    assert len(filled.samples) >= 40 and len(filled.thumb_box.children) == len(filled.samples)
    assert filled.bars.value.count('data-full="1"') == 4
    assert not filled.calibrate_button.disabled
    assert filled.commit_button.disabled  # nothing to commit before CALIBRATE
    assert not filled.loop.errors, filled.loop.last_error
    assert filled.image.value[:2] == b"\xff\xd8" and "dtscal-live" in filled.image._dom_classes


def test_calibrate_button_then_commit_to_a_folder(filled, truth, tmp_path):
    filled.calibrate_button.click()
    assert wait_for(lambda: not filled.calibrating and filled.result is not None, 120)
    K, K_true = filled.result.K, np.asarray(truth["camera"]["K"])
    for ij in [(0, 0), (1, 1), (0, 2), (1, 2)]:
        assert abs(K[ij] / K_true[ij] - 1) < 0.003, (ij, K[ij], K_true[ij])
    assert 'data-rms="' in filled.results.value and "standard deviations" in filled.results.value
    assert not filled.commit_button.disabled
    filled.folder_text.value = str(tmp_path)
    filled.commit_button.click()
    written = calib_files.load_intrinsics(tmp_path / "camera_intrinsic" / "synthbot.yaml")
    np.testing.assert_allclose(written.K, filled.result.K)
    assert "COMMIT: wrote" in filled.message.value
    # the preview shows the frame undistorted once there is a calibration
    f = next(f for f in open_source(BAG) if f.ok)
    filled.alpha.value = 1.0
    filled.loop.step(f)
    assert filled.preview.value[:2] == b"\xff\xd8"
    # the maps were made with the result (not in the frame loop); another alpha's are made in a helper
    # thread while the frames go on, and then they are the kit's own maps for that alpha
    assert wait_for(lambda: filled._preview_key == (id(filled.result), 1.0), 30)
    cam1 = filled.result.camera().with_alpha(1.0)
    for a, b in zip(filled._preview_maps, cam1.rectification_maps()):
        np.testing.assert_allclose(a, b, atol=1e-3)


def test_calibrate_runs_in_a_helper_process(filled, monkeypatch):
    """README: CALIBRATE runs in its own process, so the live image never waits for the solver.

    The solve is followed by process id: the in-process solver (patched to record the pid that runs
    it) must not run, and the solver process that answered is a child of this one, with another pid.
    """
    from dtscal_lib import pipeline, session
    from dtscal_lib.ui import intrinsic, solver

    here = []

    def in_this_process(*a, **k):
        here.append(os.getpid())
        return real(*a, **k)

    real = session.calibrate_without_outlier_views
    for module in (session, pipeline, intrinsic):  # wherever the in-process solver is reachable from
        monkeypatch.setattr(module, "calibrate_without_outlier_views", in_this_process, raising=False)
    answered = []
    real_calibrate = solver.SolverProcess.calibrate

    def calibrate(self, *a, **k):
        out = real_calibrate(self, *a, **k)
        answered.append(self._proc.pid)
        return out

    monkeypatch.setattr(solver.SolverProcess, "calibrate", calibrate)
    assert filled.prepare_calibration(wait=120)  # the helper is up (a safety net: it starts in ~2 s)
    before = filled.result
    filled.calibrate_button.click()
    assert wait_for(lambda: not filled.calibrating and filled.result is not None and filled.result is not before, 120)
    assert here == [], "CALIBRATE ran in the kernel's process"
    assert len(answered) == 1 and answered[0] != os.getpid()
    with open(f"/proc/{answered[0]}/status") as f:  # the helper is this process's child
        ppid = next(int(line.split()[1]) for line in f if line.startswith("PPid:"))
    assert ppid == os.getpid()


def test_fast_preview_maps_are_the_kits_maps():
    from dtscal_lib import duckietown as dt
    from dtscal_lib.camera import CameraModel
    from dtscal_lib.ui.intrinsic import rectification_maps_fast

    for alpha in (0.0, 1.0):
        cam = CameraModel(dt.default_K(), dt.default_dist(), dt.IMAGE_SIZE).with_alpha(alpha)
        for a, b in zip(rectification_maps_fast(cam), cam.rectification_maps()):
            np.testing.assert_allclose(a, b, atol=1e-3)
    K = dt.default_K()
    K[0, 1] = 2.0  # OpenCV ignores skew: the kit's maps are used
    skewed = CameraModel(K, dt.default_dist(), dt.IMAGE_SIZE)
    for a, b in zip(rectification_maps_fast(skewed), skewed.rectification_maps()):
        np.testing.assert_array_equal(a, b)


def test_drop_a_sample_by_its_button(filled):
    n = len(filled.samples)
    second = filled.samples[1]
    filled.thumb_box.children[0].children[1].click()
    assert len(filled.samples) == n - 1 == len(filled.thumb_box.children)
    assert filled.samples[0] is second
    assert f"samples: {n - 1}" in filled.count.value


def test_save_archive_and_recalibrate_later(filled, tmp_path):
    filled.calibrate(wait=True)  # the samples as they are now (one was dropped above)
    filled.archive_text.value = str(tmp_path / "session.zip")
    filled.save_button.click()
    assert "SAVE:" in filled.message.value, filled.message.value
    with zipfile.ZipFile(tmp_path / "session.zip") as z:
        assert {"session.json", "samples.npz", "camera_intrinsic/synthbot.yaml"} <= set(z.namelist())
    arch = load_session(tmp_path / "session.zip")
    assert len(arch.samples) == len(filled.samples) and arch.calibration is not None
    later = LiveCalibrator(str(BAG), autostart=False)
    try:
        assert "loaded" in later.load(tmp_path / "session.zip")
        assert len(later.thumb_box.children) == len(filled.samples) and not later.calibrate_button.disabled
        res = later.calibrate(wait=True)
        np.testing.assert_allclose(res.K, filled.result.K, rtol=1e-6)
    finally:
        later.close()


def test_bad_archive_is_a_message(tmp_path):
    app = LiveCalibrator(str(BAG), autostart=False)
    bad = tmp_path / "x.zip"
    bad.write_bytes(b"not a zip")
    assert "LOAD failed" in app.load(bad) and "not a zip" in app.message.value
    assert "LOAD failed" in app.load(tmp_path / "missing.zip")
    app.close()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_commit_failures_keep_the_previous_calibration(filled, tmp_path, monkeypatch):
    assert filled.result is not None or filled.calibrate(wait=True) is not None
    # 1. over ROS with no master: a clear message, the robot untouched, SAVE still works
    monkeypatch.setenv("ROS_MASTER_URI", f"http://127.0.0.1:{_free_port()}")
    filled.folder_text.value = str(tmp_path / "ros")
    filled.commit_target.value = "ros"
    msg = filled.commit()
    assert msg.startswith("COMMIT failed") and "SAVE still keeps" in msg and "Traceback" not in msg
    assert "dtscal-error" in filled.message.value
    # 2. a calibration folder that cannot be written: the previous file is intact
    folder = tmp_path / "calib"
    previous = calib_files.save_intrinsics(calib_files.IntrinsicCalibration.from_dict(
        __import__("dtscal_lib.duckietown", fromlist=["x"]).DEFAULT_INTRINSICS), folder, "synthbot")
    before = previous.read_bytes()
    os.chmod(previous.parent, 0o500)
    try:
        if os.access(previous.parent, os.W_OK):  # root ignores permissions: block the backup instead
            (previous.parent / "synthbot.yaml.bak").mkdir()
            (previous.parent / "synthbot.yaml.bak" / "keep").write_text("x")
        filled.commit_target.value = "folder"
        filled.folder_text.value = str(folder)
        msg = filled.commit()
    finally:
        os.chmod(previous.parent, 0o700)
    assert msg.startswith("COMMIT failed") and "could not be written" in msg
    assert previous.read_bytes() == before
    filled.archive_text.value = str(tmp_path / "still.zip")
    assert filled.save().startswith("SAVE:")


def test_calibrate_on_degenerate_samples_is_a_message(filled):
    app = LiveCalibrator(str(BAG), autostart=False)
    try:
        from dtscal_lib.coverage import CoverageTracker, Sample

        base = filled.samples[0]
        app.tracker = CoverageTracker(app.board, (640, 480))
        # the same board translated: parallel views, which Zhang's method cannot use
        app.tracker.samples = [Sample(base.corners + (dx, dy), base.params, i)
                               for i, (dx, dy) in enumerate([(0, 0), (5, 3), (-4, 6), (3, -5)])]
        assert app.calibrate(wait=True) is None
        assert "CALIBRATE failed" in app.results.value and app.result is None
        assert app.commit_button.disabled
        app.tracker.samples = app.tracker.samples[:2]
        assert app.calibrate(wait=True) is None and "at least 3" in app.results.value
    finally:
        app.close()


@pytest.fixture()
def short_bag(tmp_path):
    """40 frames of the recording with three corrupt JPEGs in the middle."""
    frames = []
    for i, (stamp, _, data) in enumerate(datasets.read_bag_jpegs(BAG)):
        if i >= 180:
            break
        if i % 4 == 0:
            frames.append((stamp, data))
    for k in (10, 20, 30):
        frames[k] = (frames[k][0], frames[k][1][: len(frames[k][1]) // 3])
    frames[15] = (frames[15][0], b"garbage")
    return write_compressed_image_bag(tmp_path / "short.bag", "/shortbot/camera_node/image/compressed", frames)


def test_source_ends_samples_kept_reconnect_and_corrupt_frames_counted(short_bag):
    app = LiveCalibrator(str(short_bag), realtime=False)
    try:
        assert app.robot == "shortbot"
        assert wait_for(lambda: app.state == "ended", 60)
        assert wait_for(lambda: "source ended" in app.status.value, 5)
        n = len(app.samples)
        assert "skipped frames" in app.status.value and "Traceback" not in app.status.value
        bad = app.source.status.bad
        assert sum(bad.values()) >= 3, bad
        seen = app.frames_seen
        app.reconnect_button.click()
        assert wait_for(lambda: app.frames_seen > seen, 30)
        assert len(app.samples) >= n  # nothing was forgotten
        assert not app.loop.errors, app.loop.last_error
    finally:
        app.close()


def test_odd_frames_are_counted_not_raised(filled):
    from dtscal_lib.sources.frame import Frame

    n = filled.frames_seen
    filled.loop.step(Frame(10_000, 0.0, np.zeros((480, 640), np.uint8), None, "gray"))
    filled.loop.step(Frame(10_001, 0.0, np.zeros((240, 320, 3), np.uint8), None, "small"))
    assert filled.bad["odd_frame"] == 1 and filled.bad["size_mismatch"] == 1
    assert filled.frames_seen == n and not filled.loop.errors


def test_calibrate_stays_disabled_while_a_calibration_runs(filled, monkeypatch):
    """ROS's cameracalibrator greys CALIBRATE out while it computes; here too: frames that arrive during a
    calibration (each one ready by ROS's rule) never enable it, and it comes back when the calibration ends."""
    import threading

    started, release = threading.Event(), threading.Event()
    real = filled.session.calibrate

    def held(*a, **k):
        started.set()
        assert release.wait(120), "the test never let the calibration finish"
        return real(*a, **k)

    monkeypatch.setattr(filled.session, "calibrate", held)
    monkeypatch.setattr(filled.background, "prepare", lambda wait=0.0: False)  # solve in this process
    assert not filled.calibrate_button.disabled
    filled.calibrate_button.click()
    try:
        assert started.wait(60) and filled.calibrating
        assert filled.calibrate_button.disabled
        frames = [f for _, f in zip(range(400), open_source(BAG)) if f.ok][-5:]
        for f in frames:
            filled.loop.step(f)
            assert filled.calibrate_button.disabled, "CALIBRATE enabled while a calibration runs"
    finally:
        release.set()
    assert wait_for(lambda: not filled.calibrating, 120)
    assert wait_for(lambda: not filled.calibrate_button.disabled, 30)  # enabled again once it is done


def _jpeg_size(data: bytes) -> tuple[int, int]:
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    assert img is not None, "not a JPEG a browser can show"
    return img.shape[1], img.shape[0]


def test_views_show_a_placeholder_until_frames_flow_and_an_unreachable_source_could_not_connect():
    """An empty ipywidgets Image is a broken-image icon in the browser: each view holds a picture from the start
    (the undistorted preview until CALIBRATE, the live image until the first frame); a source that failed before
    its first frame reads "could not connect: <reason>", never "source lost", and says so where the image was."""
    from dtscal_lib.sources.live import LiveStatus

    app = LiveCalibrator(str(BAG), autostart=False)
    try:
        for view in (app.image, app.preview):
            assert view.value[:2] == b"\xff\xd8" and _jpeg_size(view.value) == (640, 480)
        assert app.preview.value != app.image.value  # each says what it waits for
        before = app.image.value
        app._on_status(LiveStatus("error", "nothing listens on port 9 of 127.0.0.1; start the robot", 0))
        assert "could not connect to" in app.status.value and "nothing listens on port 9" in app.status.value
        assert "source lost" not in app.status.value
        assert app.image.value[:2] == b"\xff\xd8" and app.image.value != before
        # once frames came, losing the source is "source lost" (the samples are kept)
        f = next(f for f in open_source(BAG) if f.ok)
        app.loop.step(f)
        shown = app.image.value
        app._on_status(LiveStatus("error", "the ROS master stopped answering", 12))
        assert "source lost" in app.status.value and "could not connect" not in app.status.value
        assert app.image.value == shown  # the last frame stays on screen
    finally:
        app.close()


@pytest.mark.parametrize("state,frames", [("error", 0), ("error", 12), ("ended", 12)])
def test_the_status_line_says_press_reconnect_once(state, frames):
    """Issue 32: the ROS diagnosis ends its sentence with "then press Reconnect" and the live sources with "press
    Reconnect to try again"; the status line adds its own RECONNECT advice only to a message that has none (it read
    "...then press Reconnect. RECONNECT to try again.")."""
    from dtscal_lib.sources.live import LiveStatus
    from dtscal_lib.sources.ros_diagnosis import RECONNECT
    from dtscal_lib.ui.render import source_status_html

    for message in (f"nothing listens on port 11311 of duckie.local, {RECONNECT}", "the stream closed; press "
                    "Reconnect to try again", "the recording ended"):
        html = source_status_html("ros:duckie", LiveStatus(state, message, frames), {}, "Every sample is kept")
        assert html.lower().count("reconnect") == 1, html
        assert ".." not in html and ". ." not in html, html
