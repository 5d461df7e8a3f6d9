"""Wrong scenes are refused: mirrored frames, a board size wrong by a large factor (issue 17 item 4).

``dtscal calibrate-extrinsics`` judges the homography by what a Duckiebot is (dtscal_lib.limits: camera
0.07-0.16 m above the ground, 5-40 degrees down, from Duckietown's real fleet) and by the board seen
from above the right way round (its printed pattern's colours). A refused result exits 3 and writes
nothing; ``--keep-anyway`` writes it as ``ROBOT.rejected.yaml`` beside the robot's file (still exit 3).
The frames are the synthetic session's extrinsic recording (``data/session/extrinsics.bag``), as
recorded and mirrored. A file Duckietown reads with a malformed P row is read with a one-line warning.
"""

from __future__ import annotations

import copy
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from dtscal_lib import calib_files, datasets
from dtscal_lib import duckietown as dt

EXTRINSIC_BAG = datasets.session_dir() / "extrinsics.bag"
REFUSED = 3
ROBOT = "synthbot"


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
    calib_files.save_intrinsics(calib_files.load_intrinsics(calib_files.intrinsic_path(out, "default")), out, ROBOT)
    calib_files.save_extrinsics(dt.default_H(), out, ROBOT)
    return out


def _frames(folder: Path, flip: int | None) -> Path:
    folder.mkdir()
    for k, (_, _, data) in enumerate(datasets.read_bag_jpegs(EXTRINSIC_BAG)):
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        cv2.imwrite(str(folder / f"frame_{k:02d}.png"), img if flip is None else cv2.flip(img, flip))
        if k == 2:
            break
    return folder


def _refused_then_kept(args: list, calibrations: Path, words: list[str]) -> None:
    intr = calibrations / "camera_intrinsic" / "default.yaml"
    before = snapshot(calibrations)
    common = ["calibrate-extrinsics", *args, "--intrinsics", intr, "--robot", ROBOT, "--out", calibrations, "-q"]
    p = dtscal(*common)
    assert p.returncode == REFUSED, p.stderr
    assert "Traceback" not in p.stderr and f"refusing to write camera_extrinsic/{ROBOT}.yaml" in p.stderr
    for w in words:
        assert w in p.stderr, p.stderr
    assert snapshot(calibrations) == before  # nothing written

    p = dtscal(*common, "--keep-anyway", "--json")
    assert p.returncode == REFUSED, p.stderr
    kept = calibrations / "camera_extrinsic" / f"{ROBOT}.rejected.yaml"
    assert json.loads(p.stdout)["output"] == str(kept)
    after = snapshot(calibrations)
    assert after.pop(f"camera_extrinsic/{ROBOT}.rejected.yaml")
    assert after == before  # the robot's own file untouched


def test_mirrored_frames_are_refused_and_kept_beside_on_request(tmp_path, calibrations):
    _refused_then_kept(["--source", _frames(tmp_path / "mirrored", 1)], calibrations,
                       ["the board is seen mirrored", "not mirrored ones"])


def test_the_same_frames_unmirrored_are_written(tmp_path, calibrations):
    intr = calibrations / "camera_intrinsic" / "default.yaml"
    p = dtscal("calibrate-extrinsics", "--source", _frames(tmp_path / "plain", None), "--intrinsics", intr,
               "--robot", ROBOT, "--out", calibrations, "-q", "--json")
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert out["doubts"] == [] and out["output"] == str(calibrations / "camera_extrinsic" / f"{ROBOT}.yaml")
    assert 0.07 < out["camera_pose"]["height_m"] < 0.16


def test_board_size_wrong_by_a_factor_of_three_is_refused(calibrations):
    # the 31 mm board declared as 0.1 m: the camera would be 0.335 m above the ground
    _refused_then_kept(["--source", EXTRINSIC_BAG, "--square", "0.1"], calibrations,
                       ["m above the ground (a Duckiebot's camera: 0.07-0.16 m)", "times smaller than --square"])


def test_intrinsic_file_with_a_malformed_P_row_warns_and_calibrates(tmp_path, calibrations):
    doc = copy.deepcopy(dt.DEFAULT_INTRINSICS)
    doc["projection_matrix"]["data"][11] = 1  # third row [0, 0, 1, 1], as Duckietown's DD24 file
    intr = tmp_path / "dd24.yaml"
    intr.write_text(yaml.safe_dump(doc))
    p = dtscal("calibrate-extrinsics", "--source", EXTRINSIC_BAG, "--intrinsics", intr, "--robot", ROBOT,
               "--out", calibrations, "-q")
    assert p.returncode == 0, p.stderr
    warnings = [line for line in p.stderr.splitlines() if line.startswith("dtscal: warning:")]
    assert len(warnings) == 1 and "third row" in warnings[0] and str(intr) in warnings[0], p.stderr
    assert "Traceback" not in p.stderr and "Warning" not in p.stderr
