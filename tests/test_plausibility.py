"""The kit refuses to write a calibration it does not believe (exit code 3), and keeps it beside on request.

Reproductions of the issue through the ``dtscal`` command: forty in-plane-shifted copies of one
frame (fx = 186 where the truth is 308), and ``calibrate-extrinsics`` on the hand-held intrinsic
recording (a homography putting the image centre 0.9 m to the left). Each must exit 3, say why
and what to do, and leave the previous calibration file intact; ``--keep-anyway`` writes the
result as ``ROBOT.rejected.yaml`` beside it.
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from dtscal_lib import calib_files, datasets, pipeline
from dtscal_lib import duckietown as dt
from dtscal_lib.boards import DUCKIETOWN_BOARD
from dtscal_lib.calibration import calibrate
from dtscal_lib.camera import project_points
from dtscal_lib.detect import detect_board
from dtscal_lib.errors import ImplausibleCalibrationError
from dtscal_lib.ground import camera_pose_from_homography, ground_homography_doubts
from dtscal_lib.plausibility import distinct_board_images, intrinsic_doubts

SESSION = datasets.session_dir()
INTRINSIC_BAG = SESSION / "intrinsics.bag"
EXTRINSIC_BAG = SESSION / "extrinsics.bag"
REFUSED = 3


def dtscal(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "dtscal_lib.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=600, check=False)


def snapshot(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture
def calibrations(tmp_path) -> Path:
    """A calibrations folder with a previous calibration of synthbot."""
    out = tmp_path / "calibrations"
    calib_files.write_defaults(out)
    calib = calib_files.load_intrinsics(calib_files.intrinsic_path(out, "default"))
    calib_files.save_intrinsics(calib, out, "synthbot")
    calib_files.save_extrinsics(dt.default_H(), out, "synthbot")
    return out


# --------------------------------------------------------------------------- intrinsics, through the CLI
@pytest.fixture(scope="module")
def shifted_copies(tmp_path_factory) -> Path:
    """Forty copies of one session frame, the board shifted around the picture (no new tilt)."""
    folder = tmp_path_factory.mktemp("shifted")
    for _, _, data in datasets.read_bag_jpegs(INTRINSIC_BAG):
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        det = detect_board(img, DUCKIETOWN_BOARD)
        if det.found and np.all(np.ptp(det.corners, axis=0) < (200, 160)):
            break
    lo, hi = det.corners.min(axis=0), det.corners.max(axis=0)
    rng = np.random.default_rng(0)
    k = 0
    while k < 40:
        d = rng.uniform(-150, 150, 2)
        if (lo + d).min() < 60 or (hi + d)[0] > 580 or (hi + d)[1] > 420:
            continue
        M = np.float32([[1, 0, d[0]], [0, 1, d[1]]])
        cv2.imwrite(str(folder / f"copy_{k:02d}.png"),
                    cv2.warpAffine(img, M, (640, 480), borderMode=cv2.BORDER_REPLICATE))
        k += 1
    return folder


def test_shifted_copies_refused_and_previous_file_kept(shifted_copies, calibrations):
    before = snapshot(calibrations)
    p = dtscal("calibrate-intrinsics", "--source", shifted_copies, "--robot", "synthbot", "--out", calibrations, "-q")
    assert p.returncode == REFUSED, p.stderr
    assert "Traceback" not in p.stderr
    assert "refusing to write camera_intrinsic/synthbot.yaml" in p.stderr
    assert "1 distinct board image" in p.stderr and "Tilt and turn the board" in p.stderr
    assert "--keep-anyway" in p.stderr and "keep_anyway" not in p.stderr
    assert snapshot(calibrations) == before

    p = dtscal("calibrate-intrinsics", "--source", shifted_copies, "--robot", "synthbot", "--out", calibrations,
               "-q", "--keep-anyway", "--json")
    assert p.returncode == REFUSED, p.stderr
    out = json.loads(p.stdout)
    kept = calibrations / "camera_intrinsic" / "synthbot.rejected.yaml"
    assert out["output"] == str(kept) and out["doubts"]
    assert "kept as" in p.stderr and str(kept) in p.stderr
    after = snapshot(calibrations)
    assert after.pop("camera_intrinsic/synthbot.rejected.yaml")
    assert after == before  # synthbot.yaml and its backup untouched
    fx = calib_files.load_intrinsics(kept).K[0, 0]
    assert abs(fx / dt.default_K()[0, 0] - 1) > 0.05  # indeed wrong: the refusal was right


def test_library_raises_with_the_doubts(shifted_copies, tmp_path):
    with pytest.raises(ImplausibleCalibrationError) as e:
        pipeline.calibrate_intrinsics(shifted_copies, robot="bot", out_dir=tmp_path)
    assert any("distinct board image" in d for d in e.value.doubts)
    assert not (tmp_path / "camera_intrinsic").exists()
    run = pipeline.calibrate_intrinsics(shifted_copies, robot="bot", out_dir=None, keep_anyway=True)
    assert run.doubts and run.path is None


# --------------------------------------------------------------------------- intrinsics, the checks
def _views(n, seed, tilt=0.5, base=(0.0, 0.0), noise=0.1):
    rng = np.random.default_rng(seed)
    obj = DUCKIETOWN_BOARD.object_points()
    imgs, tries = [], 0
    while len(imgs) < n and tries < 100 * n:
        tries += 1
        r = np.array([base[0] + rng.uniform(-tilt, tilt), base[1] + rng.uniform(-tilt, tilt), rng.uniform(-0.3, 0.3)])
        R = cv2.Rodrigues(r)[0]
        t = np.array([rng.uniform(-0.08, 0.08), rng.uniform(-0.06, 0.06), rng.uniform(0.3, 0.5)])
        t -= R @ DUCKIETOWN_BOARD.centre
        try:
            p = project_points(obj, r, t, dt.default_K(), dt.default_dist())
        except ValueError:
            continue
        if p.min() > 10 and p[:, 0].max() < 630 and p[:, 1].max() < 470:
            imgs.append(p + rng.normal(0, noise, p.shape))
    assert len(imgs) == n
    return [obj] * n, imgs


@pytest.fixture(scope="module")
def good():
    objs, imgs = _views(25, 1)
    return calibrate(objs, imgs, dt.IMAGE_SIZE), imgs


def test_good_calibration_has_no_doubts(good):
    res, imgs = good
    assert intrinsic_doubts(res, imgs) == []


def test_too_little_tilt():
    objs, imgs = _views(25, 2, tilt=0.05, base=(0.35, 0.0))
    res = calibrate(objs, imgs, dt.IMAGE_SIZE)
    doubts = intrinsic_doubts(res, imgs)
    assert any("tilted too little" in d for d in doubts), doubts


def test_high_rms():
    objs, imgs = _views(25, 3, noise=1.5)
    res = calibrate(objs, imgs, dt.IMAGE_SIZE)
    assert any("reprojection RMS" in d for d in intrinsic_doubts(res, imgs))


@pytest.mark.parametrize("change, words", [
    ({"fx": 20.0, "fy": 20.0}, "field of view"),
    ({"fx": 20000.0, "fy": 20000.0}, "field of view"),
    ({"fx": 450.0}, "fx / fy"),
    ({"cx": 40.0}, "principal point"),
    ({"cy": 460.0}, "principal point"),
])
def test_physically_implausible_values(good, change, words):
    res, _ = good
    K = res.K.copy()
    idx = {"fx": (0, 0), "fy": (1, 1), "cx": (0, 2), "cy": (1, 2)}
    for k, v in change.items():
        K[idx[k]] = v
    doubts = intrinsic_doubts(dataclasses.replace(res, K=K))
    assert any(words in d for d in doubts), doubts


def test_undetermined_focal_length(good):
    res, _ = good
    std = dict(res.std, fx=0.05 * res.K[0, 0])
    assert any("determined only to" in d for d in intrinsic_doubts(dataclasses.replace(res, std=std)))


def test_distinct_board_images():
    p = DUCKIETOWN_BOARD.object_points()[:, :2] * 1000
    assert distinct_board_images([p + d for d in np.random.default_rng(0).uniform(-100, 100, (40, 2))]) == 1
    assert distinct_board_images([p, p * 1.1, p[::-1] * 0.9, p[:20]]) == 4


# --------------------------------------------------------------------------- extrinsics
def _ground_H(height=0.1, pitch_deg=18.0, yaw_deg=0.0, x=0.06, y=0.0, K=None):
    """Rectified-pixel -> ground homography of a camera at (x, y, height) looking pitch_deg down."""
    K = dt.default_K() if K is None else K
    p, a = np.radians(pitch_deg), np.radians(yaw_deg)
    z = np.array([np.cos(p) * np.cos(a), np.cos(p) * np.sin(a), -np.sin(p)])  # optical axis, robot frame
    xc = np.cross(z, [0.0, 0.0, 1.0])
    xc /= np.linalg.norm(xc)  # image x: to the camera's right
    R = np.array([xc, np.cross(z, xc), z])  # robot -> camera
    t = -R @ np.array([x, y, height])
    H = np.linalg.inv(K @ np.column_stack([R[:, 0], R[:, 1], t]))
    return H / H[2, 2]


def test_pose_recovered_from_a_known_homography():
    pose = camera_pose_from_homography(_ground_H(0.12, 22.0, 5.0, 0.05, 0.01), dt.default_K())
    assert pose["height_m"] == pytest.approx(0.12, abs=1e-9)
    assert pose["pitch_down_deg"] == pytest.approx(22.0, abs=1e-7)
    assert pose["yaw_deg"] == pytest.approx(5.0, abs=1e-7)
    assert pose["position_m"] == pytest.approx([0.05, 0.01], abs=1e-9)
    assert ground_homography_doubts(_ground_H(), dt.default_K()) == []


@pytest.mark.parametrize("kw, words", [
    ({"height": 0.9}, "above the ground"),
    ({"height": 0.005}, "above the ground"),
    ({"pitch_deg": -10.0}, "below the horizon"),
    ({"pitch_deg": 88.0}, "below the horizon"),
    ({"yaw_deg": 89.0}, "to the side"),
    ({"x": 0.3}, "ahead of the axle"),
])
def test_implausible_ground_cameras(kw, words):
    doubts = ground_homography_doubts(_ground_H(**kw), dt.default_K())
    assert any(words in d for d in doubts), doubts


def test_homography_through_the_wrong_intrinsics():
    K_wrong = dt.default_K() @ np.diag([1.6, 1.0, 1.0])  # fx off by 60 %
    doubts = ground_homography_doubts(_ground_H(K=K_wrong), dt.default_K())
    assert any("not a view of a flat ground" in d for d in doubts), doubts


def test_h12_sign_flipped_is_not_a_view_of_the_ground():
    H = _ground_H()
    H[1, 2] = abs(H[1, 2])
    codes = {d.code for d in ground_homography_doubts(H, dt.default_K())}
    assert "not_a_plane_view" in codes, codes


@pytest.mark.parametrize("height, pitch", [(0.10, 16.0), (0.11, 24.0)])
def test_upside_down_camera_of_the_fleet_is_believed(height, pitch):
    """The fleet's H[1][2] > 0 files: the image rotated 180 degrees and the corners ordered by their image
    position, so the ground comes out turned about the board's centre; a self-consistent camera."""
    from dtscal_lib.boards import ground_points
    R180 = np.array([[-1.0, 0, 639], [0, -1, 479], [0, 0, 1]])
    xc = ground_points(DUCKIETOWN_BOARD)[:, 0].mean()
    T = np.array([[-1.0, 0, 2 * xc], [0, -1, 0], [0, 0, 1]])
    H = T @ _ground_H(height, pitch) @ np.linalg.inv(R180)
    H /= H[2, 2]
    assert H[1, 2] > 0 and dt.homography_is_corrupt(H)
    assert ground_homography_doubts(H, dt.default_K()) == []


def test_session_extrinsics_pose_matches_truth(tmp_path):
    truth = datasets.load_truth()["extrinsics"]
    calib_files.write_defaults(tmp_path)
    run = pipeline.calibrate_extrinsics(EXTRINSIC_BAG, calib_files.intrinsic_path(tmp_path, "default"), out_dir=None)
    assert run.doubts == []
    assert run.camera_pose["height_m"] == pytest.approx(truth["camera_height_m"], abs=0.003)
    assert run.camera_pose["pitch_down_deg"] == pytest.approx(truth["camera_pitch_deg"], abs=0.5)


def test_extrinsics_on_the_handheld_recording_refused(calibrations):
    intr = calibrations / "camera_intrinsic" / "default.yaml"
    before = snapshot(calibrations)
    p = dtscal("calibrate-extrinsics", "--source", INTRINSIC_BAG, "--intrinsics", intr, "--out", calibrations, "-q")
    assert p.returncode == REFUSED, p.stderr
    assert "Traceback" not in p.stderr and "refusing to write camera_extrinsic/synthbot.yaml" in p.stderr
    assert "above the ground" in p.stderr and "to the side" in p.stderr
    assert snapshot(calibrations) == before

    p = dtscal("calibrate-extrinsics", "--source", INTRINSIC_BAG, "--intrinsics", intr, "--out", calibrations, "-q",
               "--keep-anyway")
    assert p.returncode == REFUSED, p.stderr
    kept = calibrations / "camera_extrinsic" / "synthbot.rejected.yaml"
    after = snapshot(calibrations)
    assert after.pop("camera_extrinsic/synthbot.rejected.yaml")
    assert after == before
    assert "kept as" in p.stderr and str(kept) in p.stderr
