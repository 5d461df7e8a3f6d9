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

# Duckietown's shipped files, value for value (duckietown.md)
DEFAULT_P = np.array([[210.1107940673828, 0, 327.2577820024981], [0, 253.8408660888672, 239.9969353923052],
                      [0, 0, 1]])
DEFAULT_H = np.array([-4.89775e-05, -0.0002150858, -0.1818273, 0.00099274, 1.202336e-06, -0.3280241,
                      -0.0004281805, -0.007185673, 1]).reshape(3, 3)
SQUARE, OUTER_X, OUTER_Y = 0.031, 0.160, -0.124  # boards.py CalibrationBoard8by6 (x_offset, y_offset)
ALONG, ACROSS = 6, 8  # squares away from the robot (x), across its view (y)
REFUSED = 3


def printed_board_frame(width: int = 640, height: int = 480, supersample: int = 4) -> np.ndarray:
    """The rectified camera's view of the printed sheet lying at its place: grey (h, w) uint8."""
    s = supersample
    v, u = np.mgrid[0:height * s, 0:width * s]
    pix = np.stack([(u + 0.5) / s - 0.5, (v + 0.5) / s - 0.5, np.ones(u.shape)], axis=-1)
    g = pix @ DEFAULT_H.T
    x, y = g[..., 0] / g[..., 2], g[..., 1] / g[..., 2]
    i = np.floor((x - OUTER_X) / SQUARE)  # 0 = the row of squares nearest the robot
    j = np.floor((y - OUTER_Y) / SQUARE)  # 0 = the column on the robot's right
    on_board = (i >= 0) & (i < ALONG) & (j >= 0) & (j < ACROSS)
    white = (i + j) % 2 == 0  # (0, 0), the near-right corner square, is white
    on_paper = (np.abs(x - (OUTER_X + ALONG * SQUARE / 2)) < 0.297 / 2) & (np.abs(y) < 0.420 / 2)  # A3 sheet
    grey = np.where(on_board, np.where(white, 235.0, 25.0), np.where(on_paper, 235.0, 110.0))
    below = np.sign(g[..., 2]) == np.sign((DEFAULT_H @ [width / 2, height - 1.0, 1.0])[2])
    grey = np.where(below, grey, 110.0)  # above the horizon: the room
    grey = grey.reshape(height, s, width, s).mean(axis=(1, 3))
    noise = np.random.default_rng(21).normal(0.0, 2.0, grey.shape)
    return np.clip(np.rint(grey + noise), 0, 255).astype(np.uint8)


def layout_of(image: np.ndarray) -> dict:
    """The colours of the four corner squares, read back through the default homography."""
    inv = np.linalg.inv(DEFAULT_H)
    out = {}
    for name, (i, j) in {"near-right": (0, 0), "near-left": (0, ACROSS - 1), "far-left": (ALONG - 1, ACROSS - 1),
                         "far-right": (ALONG - 1, 0)}.items():
        p = inv @ [OUTER_X + (i + 0.5) * SQUARE, OUTER_Y + (j + 0.5) * SQUARE, 1.0]
        out[name] = "white" if image[int(round(p[1] / p[2])), int(round(p[0] / p[2]))] > 128 else "black"
    return out


def intrinsic_file(path: Path) -> Path:
    """A camera without distortion whose K is the default file's rectified P: its frames are rectified."""
    K = DEFAULT_P.ravel().tolist()
    doc = {"image_width": 640, "image_height": 480, "camera_name": "/layoutbot/camera_node",
           "camera_matrix": {"rows": 3, "cols": 3, "data": K}, "distortion_model": "plumb_bob",
           "distortion_coefficients": {"rows": 1, "cols": 5, "data": [0.0] * 5},
           "rectification_matrix": {"rows": 3, "cols": 3, "data": [1, 0, 0, 0, 1, 0, 0, 0, 1]},
           "projection_matrix": {"rows": 3, "cols": 4, "data": [*K[0:3], 0, *K[3:6], 0, *K[6:9], 0]}}
    path.write_text(yaml.safe_dump(doc))
    return path


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
