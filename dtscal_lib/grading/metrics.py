"""The runtime's metrics of the noisy checks, and where their tolerances are stored.

The grader judges a noisy answer by its distance from the ground truth (:mod:`.checks`);
the offline script that derives how far a correct answer may land (:mod:`.tolerances`, a
Monte Carlo over the accepted formulations) measures with the same functions. Both import
them from here: the metric library depends on nothing of the grader, so neither the
runtime nor the script reaches into the other (no import circle, tests/test_import_cycles.py).
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

#: the check parameters that shape the inputs (name, weight, seed and judge settings do not)
SHAPE_KEYS = ("views", "n", "sigma", "camera", "offset", "span", "random_scale")
#: the judges of noisy checks (each compares one statistic below with a derived tolerance)
NOISY_JUDGES = ("truth_H", "truth_K", "truth_pose")


def shape_key(func: str, spec: dict) -> str:
    """The key of a check in the tolerance file: function and input-shaping parameters."""
    return func + json.dumps({k: spec[k] for k in SHAPE_KEYS if k in spec}, sort_keys=True)


def apply_homography(H, pts) -> np.ndarray:
    """``pts`` (N, 2) mapped by ``H`` (OpenCV's perspectiveTransform, the independent reference)."""
    return cv2.perspectiveTransform(np.asarray(pts, float).reshape(-1, 1, 2), np.asarray(H, float)).reshape(-1, 2)


def rotation_deg(Ra, Rb) -> float:
    """Angle of the rotation taking ``Rb`` to ``Ra``, in DEGREES."""
    return float(np.degrees(np.arccos(np.clip((np.trace(np.asarray(Ra).T @ np.asarray(Rb)) - 1) / 2, -1.0, 1.0))))


def truth_rms_px(H, H_true, src) -> float:
    """RMS distance (pixels) between ``H`` and ``H_true`` applied to the source points ``src``."""
    return float(np.sqrt(np.mean(np.sum((apply_homography(H, src) - apply_homography(H_true, src)) ** 2, axis=1))))


def K_max_px(K, K_true) -> float:
    """Largest difference (pixels) over fx, s, cx, fy, cy."""
    idx = ([0, 0, 0, 1, 1], [0, 1, 2, 1, 2])
    return float(np.abs(np.asarray(K, float)[idx] - np.asarray(K_true, float)[idx]).max())


def pose_errors(R, t, R_true, t_true) -> tuple[float, float]:
    """(rotation error in degrees, |t - t_true| / |t_true|)."""
    t = np.asarray(t, float).reshape(3)
    return rotation_deg(R, R_true), float(np.linalg.norm(t - t_true) / np.linalg.norm(t_true))


def tolerance_file(root) -> Path:
    return Path(root) / "grading" / "tolerances.json"


def load(root) -> dict:
    """The stored tolerances of the kit at ``root`` (empty when the file is absent)."""
    f = tolerance_file(root)
    return json.loads(f.read_text()) if f.is_file() else {}
