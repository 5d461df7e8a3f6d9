"""Duckietown's names (topics, services, paths, ports) are spelled in ``dtscal_lib/duckietown.py`` only.

Every other module of the kit imports them (issue 30: ``robot.py``, ``calib_files.py``, ``sources/live.py`` and
``sources/ros_diagnosis.py`` once wrote them out by hand). The check reads the code's own string and number
literals (docstrings and comments are prose, not names the code uses) and looks for any of Duckietown's.
"""

from __future__ import annotations

import ast
from pathlib import Path

from dtscal_lib import duckietown as dt

PACKAGE = Path(__file__).resolve().parents[1] / "dtscal_lib"
#: pieces of Duckietown's names that no other module may spell (each a part of a constant of duckietown.py)
NAMES = ("camera_node", "set_camera_info", "/data/config", "calibrations/camera_", "sensor/camera", "front_center",
         "data/calibration", "/image/compressed", "/files/data")
PORTS = (dt.ROS_MASTER_PORT, dt.DTPS_SWITCHBOARD_PORT, dt.KVSTORE_PORT, dt.DTPS_DUCKIEMATRIX_PORT)
#: modules that may spell them, and why
PROSE = {
    "sources/ros_helper.py": "runs on Debian's python, outside the kit's environment: it cannot import the kit",
    "teaching/release.py": "the students' README, prose for people (like docs/)",
    "limits.py": "its rows cite where a number comes from: a path in Duckietown's repository",
}


def _docstrings(tree) -> set[int]:
    ids = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                ids.add(id(body[0].value))
    return ids


def copies_in(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    docs = _docstrings(tree)
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Constant) or id(node) in docs:
            continue
        if isinstance(node.value, str):
            found += [f"{path.relative_to(PACKAGE)}:{node.lineno}: {name!r}" for name in NAMES if name in node.value]
            found += [f"{path.relative_to(PACKAGE)}:{node.lineno}: port {p}" for p in PORTS if str(p) in node.value]
        elif isinstance(node.value, int) and node.value in PORTS:
            found.append(f"{path.relative_to(PACKAGE)}:{node.lineno}: port {node.value}")
    return found


def test_the_names_are_in_duckietown_py_and_nowhere_else():
    copies = [c for p in sorted(PACKAGE.rglob("*.py")) if p.name != "duckietown.py"
              and p.relative_to(PACKAGE).as_posix() not in PROSE for c in copies_in(p)]
    assert copies == [], "Duckietown's names written out by hand (import them from dtscal_lib.duckietown):\n" \
        + "\n".join(copies)


def test_the_check_finds_a_copy(tmp_path):
    p = PACKAGE / "_names_probe_tmp.py"
    try:
        p.write_text('"""Doc: /ROBOT/camera_node/ is fine here."""\nTOPIC = "/{r}/camera_node/image/compressed"\n'
                     "PORT = 11911\n")
        assert copies_in(p) == ["_names_probe_tmp.py:2: 'camera_node'", "_names_probe_tmp.py:2: '/image/compressed'",
                                "_names_probe_tmp.py:3: port 11911"]
    finally:
        p.unlink()


def test_the_names_are_duckietowns():
    """The constants as Duckietown's code spells them (duckietown.md, duckietown-sdk, dt-kvstore)."""
    assert dt.ros_name(dt.IMAGE_TOPIC, "autobot01") == "/autobot01/camera_node/image/compressed"
    assert dt.ros_name(dt.SET_CAMERA_INFO_SERVICE, "autobot01") == "/autobot01/camera_node/set_camera_info"
    assert "/".join((*dt.dtps_camera_path("autobot01"), dt.DTPS_CAMERA_JPEG)) == \
        "autobot01/sensor/camera/front_center/jpeg"
    assert "/".join(dt.kvstore_calibration_path("camera_intrinsic")) == "data/calibration/camera_intrinsic/current"
    assert (dt.DTPS_SWITCHBOARD_PORT, dt.KVSTORE_PORT, dt.ROS_MASTER_PORT) == (11911, 11411, 11311)
    assert dt.ROBOT_CALIBRATIONS == "/data/config/calibrations"
