"""Duckietown's printed extrinsic board as it is, drawn here from its documented layout, not by the kit's renderer.

Source of the layout: ``duckietown.md`` (Duckietown's A3 extrinsic pattern, rev 04/2024, as printed, checked
against real Duckiebot and simulator frames): 8 squares across the robot's view, 6 away from it; the corner
square nearest the robot on its right is white, the one on its left black, far-left white, far-right black.
Its place (lib-dt-computer-vision ``boards.py``, ``CalibrationBoard8by6``): the board's outer corner at
x = 0.160 m, y = -0.124 m, 31 mm squares. The frame is that sheet seen through Duckietown's shipped default
homography (``camera_extrinsic/default.yaml``) with a camera without distortion whose K is the default file's
rectified P, so the frame is its own rectified image. A few lines of numpy, no kit code.

Such a frame calibrates (exit 0, a homography written), its left-right mirror image is refused (exit 3,
nothing written), in the command line and in notebook 06's live tool alike.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from drawn_ground import ACROSS, ALONG, DEFAULT_H, OUTER_X, OUTER_Y, intrinsic_file, printed_board_frame
from drawn_ground import DUCKIEBOT_SQUARE as SQUARE

REFUSED = 3


def layout_of(image: np.ndarray) -> dict:
    """The colours of the four corner squares, read back through the default homography."""
    inv = np.linalg.inv(DEFAULT_H)
    out = {}
    for name, (i, j) in {"near-right": (0, 0), "near-left": (0, ACROSS - 1), "far-left": (ALONG - 1, ACROSS - 1),
                         "far-right": (ALONG - 1, 0)}.items():
        p = inv @ [OUTER_X + (i + 0.5) * SQUARE, OUTER_Y + (j + 0.5) * SQUARE, 1.0]
        out[name] = "white" if image[int(round(p[1] / p[2])), int(round(p[0] / p[2]))] > 128 else "black"
    return out


def dtscal(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "dtscal_lib.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=600, check=False)


@pytest.fixture(scope="module")
def frame() -> np.ndarray:
    return printed_board_frame()


def test_the_drawn_frame_shows_the_documented_layout(frame):
    assert layout_of(frame) == {"near-right": "white", "near-left": "black", "far-left": "white",
                                "far-right": "black"}


def _run(tmp_path: Path, image: np.ndarray, name: str):
    src = tmp_path / name
    src.mkdir()
    cv2.imwrite(str(src / "frame.png"), image)
    out = tmp_path / f"out-{name}"
    intr = intrinsic_file(tmp_path / f"{name}-intrinsics.yaml")
    p = dtscal("calibrate-extrinsics", "--source", src, "--intrinsics", intr, "--robot", "layoutbot",
               "--out", out, "-q", "--json")
    return p, out


def test_the_printed_board_calibrates_and_its_mirror_image_is_refused(tmp_path, frame):
    p, out = _run(tmp_path, frame, "real")
    assert p.returncode == 0, p.stderr
    res = json.loads(p.stdout)
    assert res["doubts"] == []
    H = np.array(yaml.safe_load((out / "camera_extrinsic" / "layoutbot.yaml").read_text())["homography"])
    H = H.reshape(3, 3)
    # the ground under the image's pixels is where Duckietown's default homography puts it (within 5 mm)
    pix = np.array([[320.0, 479.0], [320.0, 300.0], [160.0, 400.0], [480.0, 400.0]])
    hom = np.column_stack([pix, np.ones(len(pix))])

    def ground(M):
        g = hom @ M.T
        return g[:, :2] / g[:, 2:]
    assert np.abs(ground(H) - ground(DEFAULT_H)).max() < 0.005
    assert 0.07 < res["camera_pose"]["height_m"] < 0.16

    p, out = _run(tmp_path, cv2.flip(frame, 1), "mirrored")
    assert p.returncode == REFUSED, p.stderr
    assert "the board is seen mirrored" in p.stderr and "Traceback" not in p.stderr
    assert not (out / "camera_extrinsic" / "layoutbot.yaml").exists()  # nothing written for the robot


def test_notebook_06_tool_gives_the_same_answers(tmp_path, frame):
    from dtscal_lib.sources.frame import Frame
    from dtscal_lib.ui import LiveExtrinsics

    for image, written in ((frame, True), (cv2.flip(frame, 1), False)):
        name = "real" if written else "mirrored"
        src = tmp_path / f"src-{name}"
        src.mkdir()
        cv2.imwrite(str(src / "frame.png"), image)
        out = tmp_path / name
        tool = LiveExtrinsics(str(src), intrinsics=str(intrinsic_file(tmp_path / "intr.yaml")), robot="layoutbot",
                              calibration_dir=out, autostart=False)
        try:
            tool.loop.step(Frame(0, 0.0, cv2.cvtColor(image, cv2.COLOR_GRAY2BGR), None, "frame.png"))
            assert tool.best is not None, tool.error_text.value
            said = tool.save()
            assert (out / "camera_extrinsic" / "layoutbot.yaml").exists() == written, said
            assert ("mirrored" in said) != written, said
        finally:
            tool.close()
