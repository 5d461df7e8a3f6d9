"""Self-checks for notebook 01, pinhole projection (eqs. (1)-(2)).

``check_project_points(fn)`` tests a student's ``project_points(K, R, t, X) -> (N, 2)``
against OpenCV's ``cv2.projectPoints`` and against pixels known by construction (a pixel
is chosen first and a 3-D point placed on its ray), never against a second copy of the
solution.

Later cells use the course's one fallback contract, :func:`dtscal_lib.teaching.course.use_or_fallback`.
"""

from __future__ import annotations

from typing import Callable

import cv2
import numpy as np

from ...boards import DUCKIETOWN_BOARD
from ...camera import intrinsic_matrix
from ...mistakes import K_PROBE
from ...poses import points_on_rays, random_board_pose
from .core import Case, CheckFailed, Report, expect_close, expect_shape, run_check

__all__ = ["check_project_points", "K_DUCKIE", "K_SKEWED"]

#: a Duckiebot-like camera (fx, fy, cx, cy near the shipped default.yaml)
K_DUCKIE = intrinsic_matrix(307.7, 315.0, 329.7, 244.5)
#: the same with a visible skew: catches code that ignores K[0, 1]
K_SKEWED = K_PROBE


# --------------------------------------------------------------------------- the check
def _call(fn, K, R, t, X, n):
    args = [np.array(a, dtype=np.float64, copy=True) for a in (K, R, t, X)]
    out = expect_shape(fn(*args), (n, 2), "project_points(K, R, t, X)")
    for a, b, name in zip(args, (K, R, t, X), ("K", "R", "t", "X")):
        if not np.array_equal(a, np.asarray(b, dtype=np.float64)):
            raise CheckFailed(f"project_points changed its input {name}; work on copies")
    return out


def _case_axis(fn):
    R, t = np.eye(3), np.zeros(3)
    X = np.array([[0.0, 0.0, 0.5], [0.0, 0.0, 2.0]])
    expect_close(_call(fn, K_DUCKIE, R, t, X, 2), np.tile(K_DUCKIE[:2, 2], (2, 1)), 1e-9,
                 "pixels of points on the optical axis")


def _case_depth(fn):
    R, t = np.eye(3), np.zeros(3)
    X = np.array([[0.1, 0.05, 1.0], [0.2, 0.1, 2.0], [-0.3, 0.2, 0.5]])
    fx, fy, cx, cy = K_DUCKIE[0, 0], K_DUCKIE[1, 1], K_DUCKIE[0, 2], K_DUCKIE[1, 2]
    want = np.column_stack([fx * X[:, 0] / X[:, 2] + cx, fy * X[:, 1] / X[:, 2] + cy])
    expect_close(_call(fn, K_DUCKIE, R, t, X, 3), want, 1e-9, "pixels of points in front of an unmoved camera")


def _case_on_rays(K, seed: int, n: int, what: str):
    """A case of ``n`` points put on the rays of known pixels (random pose and depths) by a camera ``K``."""
    def case(fn):
        rng = np.random.default_rng(seed)
        R, t = random_board_pose(rng)
        uv = np.column_stack([rng.uniform(20, 620, n), rng.uniform(20, 460, n)])
        X = points_on_rays(K, R, t, uv, rng.uniform(0.3, 1.5, n))
        expect_close(_call(fn, K, R, t, X, n), uv, 1e-8, what)
    return case


_case_pose = _case_on_rays(K_DUCKIE, 101, 6, "pixels of points seen by a rotated, moved camera")
_case_skew = _case_on_rays(K_SKEWED, 102, 8, "pixels with a skewed K")


def _case_opencv(fn):
    rng = np.random.default_rng(103)
    X = DUCKIETOWN_BOARD.object_points()
    for _ in range(3):
        R, t = random_board_pose(rng)
        want = cv2.projectPoints(X, cv2.Rodrigues(R)[0], t, K_DUCKIE, None)[0].reshape(-1, 2)
        expect_close(_call(fn, K_DUCKIE, R, t, X, len(X)), want, 1e-6, "board corners vs cv2.projectPoints")


def _case_one_point(fn):
    rng = np.random.default_rng(104)
    R, t = random_board_pose(rng)
    uv = np.array([[100.0, 400.0]])
    X = points_on_rays(K_DUCKIE, R, t, uv, [0.7])
    expect_close(_call(fn, K_DUCKIE, R, t, X, 1), uv, 1e-8, "a single point, X of shape (1, 3)")


def check_project_points(fn: Callable) -> Report:
    """Check ``project_points(K, R, t, X) -> (N, 2)`` (eqs. (1)-(2), no lens distortion).

    Parameters
    ----------
    fn : the student's function; K (3, 3), R (3, 3) rotation world -> camera,
        t (3,) translation, X (N, 3) world points

    Returns
    -------
    Report (also printed)
    """
    return run_check("project_points", fn, [
        Case("a point on the optical axis lands on the principal point (cx, cy)", _case_axis,
             hint="camera-frame point Xc = R X + t; homogeneous pixel K Xc; divide by its third entry"),
        Case("unmoved camera (R = I, t = 0): u = fx X/Z + cx, v = fy Y/Z + cy", _case_depth,
             hint="divide the homogeneous pixel by its third coordinate (the depth Z), after multiplying by K"),
        Case("rotated and moved camera", _case_pose,
             hint="X holds one point per ROW: the camera-frame points are X @ R.T + t (not X @ R)"),
        Case("skewed K (s = K[0, 1] != 0)", _case_skew,
             hint="multiply by the whole K of eq. (1), skew included, rather than using fx, fy, cx, cy alone"),
        Case("Duckietown board corners agree with cv2.projectPoints", _case_opencv,
             hint="compare with cv2.projectPoints(X, cv2.Rodrigues(R)[0], t, K, None) on one pose"),
        Case("a single point (N = 1)", _case_one_point,
             hint="keep the result 2-D: shape (N, 2) even when N = 1 (avoid np.squeeze)"),
    ])
