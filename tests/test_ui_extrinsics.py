"""The live extrinsic tool driven headless on the recorded extrinsic session."""

from __future__ import annotations

import time

import numpy as np
import pytest

from dtscal_lib import calib_files, datasets, ground
from dtscal_lib.camera import CameraModel
from dtscal_lib.sources import open_source
from dtscal_lib.sources.frame import Frame
from dtscal_lib.ui import LiveExtrinsics

BAG = datasets.session_dir() / "extrinsics.bag"


@pytest.fixture(scope="module")
def truth():
    return datasets.load_truth()


@pytest.fixture(scope="module")
def camera(truth):
    c = truth["camera"]
    return CameraModel(c["K"], c["dist"], (c["image_width"], c["image_height"]))


def corner_errors_mm(camera, H, truth, frame_index):
    ext = truth["extrinsics"]
    frame = ext["frames"][frame_index]
    on_ground = ground.distorted_pixel_to_ground(camera, H, np.asarray(frame["corners"]))
    return 1000 * np.linalg.norm(on_ground - np.asarray(ext["ground_points"]), axis=1)


def test_every_frame_fitted_best_kept_and_saved(camera, truth, tmp_path):
    tool = LiveExtrinsics(str(BAG), intrinsics=camera, calibration_dir=tmp_path, autostart=False)
    try:
        assert tool.robot == "synthbot" and tool.save_button.disabled
        frames = [f for f in open_source(BAG) if f.ok]
        for f in frames:
            tool.loop.step(f)
        assert not tool.loop.errors, tool.loop.last_error
        assert tool.best is not None and not tool.save_button.disabled
        best = float(tool.error_text.value.split('data-best="')[1].split('"')[0])
        assert best == pytest.approx(float(np.mean(tool.best.residual_mm)), abs=1e-3) and best < 1.0
        for img in (tool.image, tool.top, tool.grid, tool.birdseye):
            assert img.value[:2] == b"\xff\xd8"
        tool.save_button.click()
        assert "SAVE: wrote" in tool.message.value, tool.message.value
        H = calib_files.load_extrinsics(tmp_path / "camera_extrinsic" / "synthbot.yaml")
        np.testing.assert_allclose(H, tool.best.H / tool.best.H[2, 2], rtol=1e-6)
        assert corner_errors_mm(camera, H, truth, frames[0].index).max() < 3.0
        # the version-2 file holds the same homography
        tool.format.value = "2"
        tool.save()
        H2, _fmt, _ = calib_files.read_extrinsic_file(tmp_path / "camera_extrinsic" / "synthbot.yaml",
                                                     intrinsics=calib_files.IntrinsicCalibration.from_camera(
                                                         camera, "/synthbot/camera_node"))
        np.testing.assert_allclose(H2 / H2[2, 2], H / H[2, 2], rtol=1e-6, atol=1e-12)
    finally:
        tool.close()


def test_waits_for_intrinsics_from_a_calibrator_and_counts_odd_frames(tmp_path):
    class NotYet:
        def camera(self):
            return None

    tool = LiveExtrinsics(str(BAG), intrinsics=NotYet(), autostart=False)
    try:
        f = next(f for f in open_source(BAG) if f.ok)
        tool.loop.step(f)
        assert "waiting for an intrinsic calibration" in tool.error_text.value and tool.best is None
        tool.loop.step(Frame(99, 0.0, np.zeros((10, 10), np.uint8), None, "odd"))
        assert tool.bad["odd_frame"] == 1 and not tool.loop.errors
        assert "nothing to save" in tool.save()
    finally:
        tool.close()


def test_no_board_is_a_message_and_save_failure_keeps_the_file(camera, tmp_path):
    tool = LiveExtrinsics(str(BAG), intrinsics=camera, calibration_dir=tmp_path, autostart=False)
    try:
        blank = Frame(0, 0.0, np.full((480, 640, 3), 128, np.uint8), None, "blank")
        tool.loop.step(blank)
        assert "no fit on this frame" in tool.error_text.value and "not found" in tool.reason
        tool.loop.step(next(f for f in open_source(BAG) if f.ok))
        (tmp_path / "camera_extrinsic").mkdir()
        target = tmp_path / "camera_extrinsic" / "synthbot.yaml"
        target.write_text("homography: [1, 0, 0, 0, 1, 0, 0, 0, 1]\n")
        before = target.read_bytes()
        tool.folder_text.value = str(target)  # a file where a folder is expected: cannot be written
        assert tool.save().startswith("SAVE failed")
        assert target.read_bytes() == before
    finally:
        tool.close()


def test_runs_live_on_the_recording(camera):
    tool = LiveExtrinsics(str(BAG), intrinsics=camera, realtime=True, loop=True)
    try:
        end = time.monotonic() + 60
        while tool.best is None and time.monotonic() < end:
            time.sleep(0.1)
        assert tool.best is not None and tool.state == "running"
        assert "live:" in tool.status.value
    finally:
        tool.close()


def test_rectification_maps_made_once_by_opencv_give_the_same_fit(camera):
    """The tool rectifies with OpenCV's maps made once per calibration (the kit's numpy maps took
    ~0.1 s per frame); they are the kit's maps, and the fit on a frame is the same."""
    from dtscal_lib.ui.extrinsic import _MapsCamera

    fast = _MapsCamera(camera.K, camera.dist, camera.size, camera.model, camera.P)
    for a, b in zip(fast.rectification_maps(), camera.rectification_maps()):
        np.testing.assert_allclose(a, b, atol=1e-3)
    assert fast.rectification_maps() is fast.rectification_maps()  # made once
    frame = next(f for f in open_source(BAG) if f.ok)
    np.testing.assert_allclose(ground.extrinsics_from_image(frame.image, fast).H,
                               ground.extrinsics_from_image(frame.image, camera).H, rtol=1e-6, atol=1e-9)


def test_views_show_a_placeholder_until_the_first_fit(camera, tmp_path):
    """No empty image (a broken-image icon in the browser): every view holds a picture that says what comes there."""
    import cv2

    tool = LiveExtrinsics(str(BAG), intrinsics=camera, calibration_dir=tmp_path, autostart=False)
    try:
        views = (tool.image, tool.top, tool.grid, tool.birdseye)
        for view in views:
            img = cv2.imdecode(np.frombuffer(view.value, np.uint8), cv2.IMREAD_COLOR)
            assert img is not None and img.shape[0] > 100
        assert len({v.value for v in views}) == 4
    finally:
        tool.close()
