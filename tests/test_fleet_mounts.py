"""Every robot as it is mounted: an upside-down Duckiebot camera, a mirrored DD24 frame.

The frames are drawn from the documented layouts, not by the kit's renderer: the Duckiebot's printed A3 board
through Duckietown's default homography (``test_board_layout.printed_board_frame``) and the DD24's A4 board at
Duckietown's reference pose (``test_dd24_reference.reference_frame``). Layouts (``duckietown.md``): both prints
have the corner square nearest the robot on its right white; the 8x6-square board is the same turned by 180
degrees, so only the perspective tells an upside-down camera (the near rows look wider).

* A camera mounted upside down sees the board's frame rotated by 180 degrees; its intrinsics are those of the
  rotated image (principal point at ``(w - 1 - cx, h - 1 - cy)``). It calibrates, the command says so in one
  line, and its homography puts every pixel where Duckietown's default homography puts the same scene point of
  the camera the right way up (within 5 mm). Its mirror image is still refused.
* A DD24 frame mirrored left-right is refused (exit 3, nothing written), as a mirrored Duckiebot frame is.
"""

from __future__ import annotations

import subprocess
import sys

import cv2
import numpy as np
import pytest
import yaml
from drawn_ground import DEFAULT_H, INTRINSICS, intrinsic_file, printed_board_frame, reference_frame
from drawn_ground import DD24_SQUARE as SQUARE

from dtscal_lib.boards import Board
from dtscal_lib.errors import ImplausibleCalibrationError
from dtscal_lib.ground import UPSIDE_DOWN_SAID
from dtscal_lib.pipeline import calibrate_extrinsics

W, H = 640, 480


@pytest.fixture(scope="module")
def frame() -> np.ndarray:
    return printed_board_frame()
TURN = np.array([[-1.0, 0, W - 1], [0, -1.0, H - 1], [0, 0, 1]])  # rotated pixel -> the upright camera's pixel


def upside_down_intrinsics(path):
    """The rectified camera of test_board_layout, as the rotated image sees it."""
    path = intrinsic_file(path)
    doc = yaml.safe_load(path.read_text())
    K = np.array(doc["camera_matrix"]["data"], float).reshape(3, 3)
    K[0, 2], K[1, 2] = W - 1 - K[0, 2], H - 1 - K[1, 2]
    doc["camera_matrix"]["data"] = K.ravel().tolist()
    doc["projection_matrix"]["data"] = np.column_stack([K, np.zeros(3)]).ravel().tolist()
    path.write_text(yaml.safe_dump(doc))
    return path


def _frames(tmp_path, image, name):
    src = tmp_path / name
    src.mkdir()
    cv2.imwrite(str(src / "frame.png"), image)
    return src


def test_an_upside_down_camera_calibrates_says_so_and_projects_right(tmp_path, frame):
    turned = cv2.rotate(frame, cv2.ROTATE_180)
    intrinsics = upside_down_intrinsics(tmp_path / "turned.yaml")
    out = tmp_path / "out"
    p = subprocess.run([sys.executable, "-m", "dtscal_lib.cli", "calibrate-extrinsics", "--source",
                        str(_frames(tmp_path, turned, "turned")), "--intrinsics", str(intrinsics), "--robot",
                        "layoutbot", "--out", str(out), "-q"], capture_output=True, text=True, timeout=600, check=False)
    assert p.returncode == 0, p.stderr
    said = [ln for ln in p.stdout.splitlines() if "upside down" in ln]
    assert said == [f"  {UPSIDE_DOWN_SAID}"], p.stdout
    Hk = np.array(yaml.safe_load((out / "camera_extrinsic" / "layoutbot.yaml").read_text())["homography"],
                  float).reshape(3, 3)
    # its right homography passes Duckietown's H[1][2] < 0 check; the fleet's 8 files of such robots with
    # H[1][2] > 0 ordered the corners by image position, which turns the ground about the board's centre
    assert Hk[1, 2] < 0
    rng = np.random.default_rng(30)
    pix = np.column_stack([rng.uniform(60, 580, 40), rng.uniform(0, 200, 40), np.ones(40)])  # below its horizon
    want, got = (TURN @ pix.T).T @ DEFAULT_H.T, pix @ Hk.T
    err = np.linalg.norm(got[:, :2] / got[:, 2:] - want[:, :2] / want[:, 2:], axis=1)
    assert err.max() < 0.005, err.max()  # metres: the near rows are the top ones, left is left

    # turned and mirrored: still refused, nothing written for the robot
    with pytest.raises(ImplausibleCalibrationError, match="the board is seen mirrored"):
        calibrate_extrinsics(str(_frames(tmp_path, cv2.flip(turned, 1), "turned-mirrored")), intrinsics,
                             robot="layoutbot", out_dir=tmp_path / "out-mirrored")
    assert not (tmp_path / "out-mirrored" / "camera_extrinsic" / "layoutbot.yaml").exists()


def test_a_camera_the_right_way_up_is_not_called_upside_down(tmp_path, frame):
    run = calibrate_extrinsics(str(_frames(tmp_path, frame, "upright")), intrinsic_file(tmp_path / "i.yaml"),
                               robot="layoutbot", out_dir=None)
    assert run.upside_down is False and run.to_dict()["upside_down"] is False


def test_a_mirrored_dd24_frame_is_refused_as_a_mirrored_duckiebot_frame_is(tmp_path):
    """The real-way-round frame calibrates as a DD24 (``test_dd24_reference``, exit 0); its mirror image does not."""
    out = tmp_path / "out"
    with pytest.raises(ImplausibleCalibrationError, match="the board is seen mirrored"):
        calibrate_extrinsics(str(_frames(tmp_path, cv2.flip(reference_frame(), 1), "dd24-mirrored")), INTRINSICS,
                             board=Board(7, 5, SQUARE), robot="dronebot", out_dir=out)
    assert not (out / "camera_extrinsic" / "dronebot.yaml").exists()
