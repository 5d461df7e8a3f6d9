"""Options and arguments are checked at the boundary, before any work: the issue's reproductions.

Every case runs through the ``dtscal`` command where the issue gives one, and checks the exit
code (2: bad input), that the message names the flag and says what to do, that there is no
traceback, and that the previous calibration file is byte for byte intact.
"""

from __future__ import annotations

import copy
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from dtscal_lib import calib_files, datasets
from dtscal_lib import duckietown as dt
from dtscal_lib.boards import DUCKIETOWN_BOARD, Board
from dtscal_lib.calibration import calibrate
from dtscal_lib.errors import CalibrationError, CalibrationFileError, DtscalError
from dtscal_lib.validation import check_board, check_image_size, check_output_folder, check_seed

from unprivileged import readable_copy, run_unprivileged, shared_tmp

SESSION = datasets.session_dir()
INTRINSIC_BAG = SESSION / "intrinsics.bag"
EXTRINSIC_BAG = SESSION / "extrinsics.bag"


def dtscal(*args, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "dtscal_lib.cli", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, timeout=600, check=False)


def refused(p: subprocess.CompletedProcess, *words: str, code: int = 2) -> None:
    assert p.returncode == code, (p.returncode, p.stderr[-2000:])
    assert "Traceback" not in p.stderr and "dtscal: error:" in p.stderr, p.stderr[-2000:]
    for w in words:
        assert w in p.stderr, (w, p.stderr)


@pytest.fixture
def calibrations(tmp_path) -> Path:
    """A calibrations folder holding a previous robot calibration (intrinsic and extrinsic)."""
    out = tmp_path / "calibrations"
    calib_files.write_defaults(out)
    calib = calib_files.load_intrinsics(calib_files.intrinsic_path(out, "default"))
    calib_files.save_intrinsics(calib, out, "synthbot")
    calib_files.save_extrinsics(dt.default_H(), out, "synthbot")
    return out


def snapshot(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


# --------------------------------------------------------------------------- board and square
@pytest.mark.parametrize("flags, words", [
    (["--board", "2x2"], ["--board 2x2", "3 to 100 inner corners"]),
    (["--board", "7x1"], ["--board 7x1"]),
    (["--board", "500x5"], ["--board 500x5"]),
    (["--square", "1e-200"], ["--square 1e-200", "metres"]),
    (["--square", "1e300"], ["--square 1e+300", "metres"]),
    (["--square", "1e20"], ["--square 1e+20"]),
    (["--square", "0"], ["--square"]),
    (["--square", "-0.031"], ["--square"]),
    (["--square", "nan"], ["--square"]),
])
def test_board_and_square_refused_before_work(calibrations, flags, words):
    check_board_flags(calibrations, "calibrate-intrinsics", flags, words)


@pytest.mark.parametrize("flags, words", [(["--board", "2x2"], ["--board 2x2"]), (["--square", "1e300"], ["--square"])])
def test_board_and_square_refused_before_work_extrinsics(calibrations, flags, words):
    check_board_flags(calibrations, "calibrate-extrinsics", flags, words)


def check_board_flags(calibrations, command, flags, words):
    before = snapshot(calibrations)
    default = calibrations / "camera_intrinsic" / "default.yaml"
    extra = ["--intrinsics", default] if command.endswith("extrinsics") else []
    p = dtscal(command, "--source", INTRINSIC_BAG, "--out", calibrations, "-q", *extra, *flags)
    refused(p, *words)
    assert snapshot(calibrations) == before


def test_check_board_library():
    assert check_board(DUCKIETOWN_BOARD) is DUCKIETOWN_BOARD
    check_board(Board(3, 3, 0.002))
    for bad in (Board(2, 5, 0.031), Board(7, 5, 1e-200), Board(7, 5, 1e300), Board(7, 5, 0.6)):
        with pytest.raises(DtscalError, match="--board|--square"):
            check_board(bad)


# --------------------------------------------------------------------------- image sizes
def _intrinsics_declaring(tmp_path, w, h) -> Path:
    doc = copy.deepcopy(dt.DEFAULT_INTRINSICS)
    doc["image_width"], doc["image_height"] = w, h
    K = doc["camera_matrix"]["data"]
    K[2], K[5] = w / 2.0, h / 2.0
    p = tmp_path / f"tiny_{w}x{h}.yaml"
    p.write_text(yaml.safe_dump(doc, default_flow_style=None, sort_keys=False))
    calib_files.load_intrinsics(p)  # a valid file: only its size is absurd
    return p


@pytest.mark.parametrize("w, h", [(1, 1), (8, 6), (20000, 480)])
def test_extrinsics_with_intrinsics_of_absurd_image_size(calibrations, tmp_path, w, h):
    intr = _intrinsics_declaring(tmp_path, w, h)
    before = snapshot(calibrations)
    p = dtscal("calibrate-extrinsics", "--source", EXTRINSIC_BAG, "--intrinsics", intr, "--out", calibrations, "-q")
    refused(p, intr.name, "image_width x image_height", "32 to 16384 pixels", "--intrinsics")
    assert snapshot(calibrations) == before


@pytest.mark.parametrize("size", [(True, 480), (640, False), (1, 480), (8, 6), (640.5, 480), ("640", 480),
                                  (640,), None, (640, 480, 3), (np.inf, 480)])
def test_calibrate_refuses_absurd_image_size(size):
    views = _views()
    with pytest.raises(CalibrationError, match="image_size"):
        calibrate(*views, size)


def test_check_image_size_accepts_whole_numbers():
    assert check_image_size((640, 480)) == (640, 480)
    assert check_image_size((np.int64(640), 480.0)) == (640, 480)
    assert check_image_size([32, 16384]) == (32, 16384)


def _views(n=12, seed=3):
    rng = np.random.default_rng(seed)
    obj = DUCKIETOWN_BOARD.object_points()
    K, dist = dt.default_K(), dt.default_dist()
    objs, imgs = [], []
    from dtscal_lib.camera import project_points
    while len(imgs) < n:
        r = rng.uniform(-0.5, 0.5, 3)
        t = np.array([rng.uniform(-0.15, 0.05), rng.uniform(-0.1, 0.0), rng.uniform(0.3, 0.5)])
        try:
            p = project_points(obj, r, t, K, dist)
        except ValueError:
            continue
        if p.min() > 10 and p[:, 0].max() < 630 and p[:, 1].max() < 470:
            objs.append(obj)
            imgs.append(p + rng.normal(0, 0.1, p.shape))
    return objs, imgs


@pytest.mark.parametrize("scale", [1e300, 1e-300, 1e12])
def test_calibrate_refuses_points_scaled_absurdly(scale):
    objs, imgs = _views()
    with pytest.raises(CalibrationError, match="object points of view 0 span"):
        calibrate([o * scale for o in objs], [i * scale for i in imgs], dt.IMAGE_SIZE)
    with pytest.raises(CalibrationError):
        calibrate(objs, [i * scale for i in imgs], dt.IMAGE_SIZE)


def test_calibrate_refuses_points_outside_the_image():
    objs, imgs = _views()
    with pytest.raises(CalibrationError, match="far outside the 320x240 image"):
        calibrate(objs, imgs, (320, 240))


def test_calibrate_still_takes_other_units():
    """Millimetres (or board squares) as the object points' unit remain fine."""
    objs, imgs = _views()
    res = calibrate([o * 1000 for o in objs], imgs, dt.IMAGE_SIZE)
    assert abs(res.K[0, 0] / dt.default_K()[0, 0] - 1) < 0.01


# --------------------------------------------------------------------------- robot names
@pytest.mark.parametrize("name, words", [
    ("DEFAULT", ["--robot DEFAULT", "never overwritten", "ignoring case"]),
    ("Default", ["--robot Default"]),
    ("a" * 64, ["64 characters", "at most 63"]),
    ("a" * 234, ["234 characters"]),
    ("a" * 250, ["250 characters"]),
    ("bot.rejected", ["'.rejected'"]),
    ("../bot", ["not valid"]),
])
def test_robot_names_refused_before_work(calibrations, name, words):
    before = snapshot(calibrations)
    p = dtscal("calibrate-intrinsics", "--source", INTRINSIC_BAG, "--out", calibrations, "-q", "--robot", name)
    refused(p, *words)
    assert snapshot(calibrations) == before


def test_longest_robot_name_can_be_recalibrated_with_backup(tmp_path):
    """63 characters: written, replaced (backup and its temporary fit), and kept beside as .rejected."""
    name = "r" * calib_files.MAX_ROBOT_NAME
    for H in (dt.default_H(), dt.default_H() * 2, dt.default_H() * 3):
        p = calib_files.save_extrinsics(H, tmp_path, name)
    calib_files.save_extrinsics(dt.default_H(), tmp_path, name, rejected=True)
    np.testing.assert_array_equal(calib_files.load_extrinsics(p.with_name(p.name + ".bak")), dt.default_H() * 2)
    assert (p.parent / f"{name}.rejected.yaml").exists()
    with pytest.raises(CalibrationFileError, match="at most 63"):
        calib_files.save_extrinsics(dt.default_H(), tmp_path, name + "r")


# --------------------------------------------------------------------------- synth
def test_synth_out_is_a_file(tmp_path):
    f = tmp_path / "afile"
    f.write_text("keep me")
    refused(dtscal("synth", "--out", f, "-q"), "--out", "is a file, not a folder")
    assert f.read_text() == "keep me"


@pytest.mark.parametrize("seed", ["-1", str(2**63)])
def test_synth_negative_seed(tmp_path, seed):
    refused(dtscal("synth", "--out", tmp_path / "data", "--seed", seed, "-q"), f"--seed {seed}", "whole number")
    assert not (tmp_path / "data").exists()


def test_output_folder_read_only_is_refused_before_work():
    """Real under root: the check runs as ``nobody`` (root ignores a folder's permissions)."""
    with shared_tmp() as d:
        ro = d / "data"
        ro.mkdir()
        os.chmod(ro, 0o555)
        ok, text = run_unprivileged(check_output_folder, ro)
        assert not ok and "--out" in text and "cannot be written to" in text, text
        ok, text = run_unprivileged(check_output_folder, ro / "session")
        assert not ok and "cannot be written to" in text, text
        assert list(ro.iterdir()) == []


def test_cli_out_read_only_folder_exit_2():
    """``dtscal synth --out`` and ``calibrate-intrinsics --out`` on a read-only folder, run as ``nobody``."""
    from dtscal_lib.cli import main

    with shared_tmp() as d:
        ro = d / "ro"
        ro.mkdir()
        os.chmod(ro, 0o555)
        ok, code = run_unprivileged(main, ["synth", "--out", str(ro / "data"), "-q"])
        assert ok and code == "2", code
        bag = readable_copy(INTRINSIC_BAG, d)  # the checkout may lie in a folder nobody cannot enter
        ok, code = run_unprivileged(main, ["calibrate-intrinsics", "--source", str(bag), "--out", str(ro), "-q"])
        assert ok and code == "2", code
        assert list(ro.iterdir()) == []


def test_check_seed():
    assert check_seed(None) is None and check_seed(0) == 0 and check_seed(2**63 - 1) == 2**63 - 1
    for bad in (-1, 2**63, True, 1.5, "3"):
        with pytest.raises(DtscalError, match="--seed"):
            check_seed(bad)


# --------------------------------------------------------------------------- wording
def test_messages_name_the_flag_not_the_keyword(tmp_path):
    (tmp_path / "a.png").write_bytes(b"\x89PNG")
    p = dtscal("calibrate-intrinsics", "--source", tmp_path, "--topic", "/x/camera_node/image/compressed",
               "--robot", "bot", "--no-write", "-q")
    refused(p, "--topic")
    assert "topic=" not in p.stderr
