"""Robot files far outside their robots' cameras load with a one-line warning (issue 21).

The ranges are Duckietown's (limits.py ``robot_fx_per_width``: real Duckiebot files have fx 305-424 px at
640 px, ``duckietown.md`` and the fleet's files with fx 417 and 424 (issue 30); ``dd24_fx_per_width``: the DD24's
own intrinsic file, fx 154.59 px at 240 px).
The files here are Duckietown's shipped default with only fx and fy changed to the values issue 21 met.
"""

from __future__ import annotations

import copy
import subprocess
import sys
import warnings
from pathlib import Path

import pytest
import yaml

from dtscal_lib import calib_files
from dtscal_lib import duckietown as dt
from dtscal_lib.errors import CalibrationFileWarning

DD24 = Path(__file__).resolve().parents[1] / "data" / "duckietown" / "dd24" / "calibration-intrinsic-dd24.yaml"


def robot_file(path: Path, fx: float, fy: float) -> Path:
    doc = copy.deepcopy(dt.DEFAULT_INTRINSICS)
    doc["camera_matrix"]["data"][0], doc["camera_matrix"]["data"][4] = fx, fy
    path.write_text(yaml.safe_dump(doc))
    return path


def load_warnings(path: Path) -> list[str]:
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        calib_files.load_intrinsics(path)
    return [str(w.message) for w in got if issubclass(w.category, CalibrationFileWarning)]


@pytest.mark.parametrize("fx, fy", [(1691.0, 1412.0), (237.0, 240.0)])
def test_far_outside_the_fleet_warns_once(tmp_path, fx, fy):
    said = load_warnings(robot_file(tmp_path / "odd.yaml", fx, fy))
    assert len(said) == 1 and f"fx {fx:.0f}" in said[0] and "outside every real" in said[0], said


@pytest.mark.parametrize("fx, fy", [(300.0, 305.0), (430.0, 428.0)])
def test_just_outside_the_fleets_real_files_warns(tmp_path, fx, fy):
    said = load_warnings(robot_file(tmp_path / "odd.yaml", fx, fy))
    assert len(said) == 1 and "305-424 px" in said[0], said


def test_real_robots_files_load_silently(tmp_path):
    assert load_warnings(robot_file(tmp_path / "fleet.yaml", 305.0, 397.0)) == []  # duckietown.md's range ends
    assert load_warnings(robot_file(tmp_path / "fleet.yaml", 417.0, 424.0)) == []  # real robots (issue 30)
    assert load_warnings(DD24) == []  # the DD24's portrait file is judged as a DD24's


def test_the_command_line_shows_it_on_one_line(tmp_path):
    odd = robot_file(tmp_path / "odd.yaml", 1691.0, 1412.0)
    p = subprocess.run([sys.executable, "-m", "dtscal_lib.cli", "calibrate-extrinsics", "--source",
                        str(tmp_path / "nothing-here"), "--intrinsics", str(odd), "--no-write", "-q"],
                       capture_output=True, text=True, timeout=300, check=False)
    lines = [ln for ln in p.stderr.splitlines() if "outside every real" in ln]
    assert len(lines) == 1 and lines[0].startswith("dtscal: warning:"), p.stderr
