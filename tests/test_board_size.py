"""A board declared smaller than it is: named with the size to pass, never calibrated into an absurd number.

OpenCV's real photographs (``data/real/opencv-samples/left``, a board of 9x6 inner corners) declared as 8x6 used
to calibrate from a sub-grid without a word, and declared as 4x3 to show a focal length of 106991.57 px (issue 21).
Now the saddles around each detection show the pattern going on (``Detection.pattern_seen``) and the calibration
is refused in words naming ``--board 9x6`` (limits.py ``pattern_continues_share``).
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from dtscal_lib.boards import parse_board
from dtscal_lib.detect import detect_board

LEFT = Path(__file__).resolve().parents[1] / "data" / "real" / "opencv-samples" / "left"


def dtscal(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "dtscal_lib.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=600, check=False)


@pytest.mark.parametrize("declared", ["8x6", "4x3"])
def test_a_board_declared_too_small_is_named_with_the_size_to_pass(tmp_path, declared):
    p = dtscal("calibrate-intrinsics", "--source", f"{LEFT}/*.jpg", "--board", declared, "--out", tmp_path / "c",
               "-q", "--robot", "bot")
    assert p.returncode == 2, p.stderr
    assert "the pattern continues past the declared corners" in p.stderr and "pass --board 9x6" in p.stderr
    assert "Traceback" not in p.stderr
    # no number of pixels at all: nothing was calibrated
    assert not re.search(r"\d+\.\d+ px", p.stdout + p.stderr), p.stdout + p.stderr
    assert not (tmp_path / "c" / "camera_intrinsic" / "bot.yaml").exists()


@pytest.mark.parametrize("declared", ["9x5", "10x6"])
def test_a_declared_board_never_found_is_refused_naming_the_size_that_is_there(tmp_path, declared):
    """9x5 (a row too few) and 10x6 (a column too many) are never found on the 9x6 board at all, so no saddle
    pattern continues past them: the refusal names the size found near the declared one (issue 31; it used to
    say "only 0 usable views ... check --board"). Exit 2, nothing written, no number of pixels."""
    p = dtscal("calibrate-intrinsics", "--source", f"{LEFT}/*.jpg", "--board", declared, "--out", tmp_path / "c",
               "-q", "--robot", "bot")
    assert p.returncode == 2, p.stderr
    assert f"the declared {declared} board was never found" in p.stderr and "pass --board 9x6" in p.stderr, p.stderr
    assert "Traceback" not in p.stderr
    assert not re.search(r"\d+\.\d+ px", p.stdout + p.stderr), p.stdout + p.stderr
    assert not (tmp_path / "c").exists() or not list((tmp_path / "c").rglob("*.yaml"))


def test_the_right_size_sees_no_bigger_pattern_and_smaller_ones_see_the_board():
    """Every photograph: declared 9x6, no view shows more; declared 8x6, every view where the board is found does."""
    images = [cv2.imread(str(f)) for f in sorted(LEFT.glob("*.jpg"))]
    assert len(images) == 13
    right = [detect_board(img, parse_board("9x6")) for img in images]
    assert sum(d.found for d in right) >= 12 and all(d.pattern_seen is None for d in right)
    small = [d for d in (detect_board(img, parse_board("8x6")) for img in images) if d.found]
    assert len(small) >= 10 and all(d.pattern_seen == (9, 6) for d in small)
    # the corners found for 8x6 are a sub-grid of the 9x6 board's: each lies on one of its corners
    k = next(i for i, d in enumerate(right) if d.found and detect_board(images[i], parse_board("8x6")).found)
    full, part = right[k].corners, detect_board(images[k], parse_board("8x6")).corners
    assert np.min(np.linalg.norm(part[:, None] - full[None], axis=2), axis=1).max() < 0.5
