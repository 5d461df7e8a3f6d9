"""Self-checks for notebook 04, lens distortion and rectification.

Expected values come from OpenCV: ``cv2.projectPoints`` with an identity camera matrix
gives distorted normalized coordinates, and ``cv2.initUndistortRectifyMap`` gives the
rectification maps. The cameras are the Duckiebot's default calibration (a wide lens with
strong barrel distortion) and a few made-up lenses with larger tangential terms.
"""

from __future__ import annotations

from typing import Callable

import cv2
import numpy as np

from ... import duckietown as dt
from ...camera import intrinsic_matrix, new_camera_matrix
from .core import Case, CheckFailed, Report, expect_close, expect_shape, run_check

__all__ = ["check_distort_normalized", "check_undistort_normalized", "check_rectification_maps",
           "opencv_distort"]

#: a lens with strong tangential terms, so a sign or an x/y swap in p1, p2 shows
DIST_TANGENTIAL = np.array([-0.12, 0.03, 0.02, -0.015, 0.0])
#: radial only, with k3
DIST_RADIAL_K3 = np.array([-0.28, 0.07, 0.0, 0.0, -0.008])


def opencv_distort(xy: np.ndarray, dist) -> np.ndarray:
    """Distorted normalized coordinates by OpenCV: ``projectPoints`` with ``K = I``, (N, 2)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    X = np.column_stack([xy, np.ones(len(xy))])
    out, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), np.eye(3), np.asarray(dist, dtype=np.float64))
    return out.reshape(-1, 2)


def _image_normalized(K, size, step: int) -> np.ndarray:
    """Distorted normalized coordinates of a pixel grid covering the image, corners included."""
    w, h = size
    us = np.unique(np.r_[np.arange(0, w, step), w - 1]).astype(float)
    vs = np.unique(np.r_[np.arange(0, h, step), h - 1]).astype(float)
    u, v = np.meshgrid(us, vs)
    Ki = np.linalg.inv(K)
    pts = np.column_stack([u.ravel(), v.ravel(), np.ones(u.size)]) @ Ki.T
    return pts[:, :2]


# --------------------------------------------------------------------------- distort_normalized
def _case_distort(dist, xy_fn, title, hint) -> Case:
    def run(fn):
        xy = xy_fn()
        got = expect_shape(fn(xy.copy(), np.array(dist, dtype=np.float64)), (len(xy), 2), "distort_normalized(xy, dist)")
        expect_close(got, opencv_distort(xy, dist), 1e-10, "distorted points (vs OpenCV)")

    return Case(title, run, hint=hint)


def _random_xy(seed, n=40, r=1.0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-r, r, size=(n, 2))


def check_distort_normalized(fn: Callable) -> Report:
    """Check ``distort_normalized(xy, dist) -> (N, 2)`` (plumb_bob) against ``cv2.projectPoints``."""
    return run_check("distort_normalized", fn, [
        _case_distort(np.zeros(5), lambda: _random_xy(1), "no distortion leaves points unchanged",
                      "with dist = 0 the result must equal the input"),
        _case_distort(np.array([-0.25, 0.0, 0.0, 0.0, 0.0]), lambda: _random_xy(2), "k1 only",
                      "radial factor: 1 + k1 r^2 + k2 r^4 + k3 r^6 with r^2 = x^2 + y^2 (r squared, not r)"),
        _case_distort(DIST_RADIAL_K3, lambda: _random_xy(3), "k1, k2 and k3 (radial)",
                      "r^4 = (r^2)^2 and r^6 = (r^2)^3; dist is ordered (k1, k2, p1, p2, k3): k3 is the LAST entry"),
        _case_distort(DIST_TANGENTIAL, lambda: _random_xy(4), "tangential terms p1, p2",
                      "x_d = x*radial + 2 p1 x y + p2 (r^2 + 2 x^2); y_d = y*radial + p1 (r^2 + 2 y^2) + 2 p2 x y "
                      "(p1 and p2 swap roles between x and y; check the signs and the factor 2)"),
        _case_distort(dt.default_dist(), lambda: _image_normalized(dt.default_K(), dt.IMAGE_SIZE, 40),
                      "the Duckiebot's default lens over the whole image",
                      "compare with cv2.projectPoints(points, 0, 0, np.eye(3), dist)"),
    ])


# --------------------------------------------------------------------------- undistort_normalized
def _case_undistort(dist, xy_true_fn, title, hint, tol=1e-8) -> Case:
    def run(fn):
        xy_true = xy_true_fn()
        xy_d = opencv_distort(xy_true, dist)
        got = expect_shape(fn(xy_d.copy(), np.array(dist, dtype=np.float64)), (len(xy_d), 2),
                           "undistort_normalized(xy_d, dist)")
        expect_close(got, xy_true, tol, "undistorted points (should re-distort to the input)")

    return Case(title, run, hint=hint)


def _duckiebot_field(region: str):
    """Undistorted normalized points whose distorted images fill (part of) the Duckiebot image."""
    K, d = dt.default_K(), dt.default_dist()
    from ...camera import undistort_normalized as _lib_undistort  # the library's Newton solver

    xy_d = _image_normalized(K, dt.IMAGE_SIZE, 32)
    r = np.hypot(xy_d[:, 0], xy_d[:, 1])
    if region == "centre":
        xy_d = xy_d[r < 1.0]
    else:  # the four image corners, where the lens bends most
        w, h = dt.IMAGE_SIZE
        corners = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], dtype=float)
        xy_d = (np.column_stack([corners, np.ones(4)]) @ np.linalg.inv(K).T)[:, :2]
    return _lib_undistort(xy_d, d)


def check_undistort_normalized(fn: Callable) -> Report:
    """Check ``undistort_normalized(xy_d, dist) -> (N, 2)``: it must invert OpenCV's distortion to 1e-8."""
    return run_check("undistort_normalized", fn, [
        _case_undistort(np.zeros(5), lambda: _random_xy(11), "no distortion leaves points unchanged",
                        "with dist = 0 the result must equal the input"),
        _case_undistort(DIST_TANGENTIAL, lambda: _random_xy(12, r=0.6), "inverts a mild lens with tangential terms",
                        "iterate until distort_normalized(x) matches xy_d to ~1e-12, not a fixed handful of steps"),
        _case_undistort(dt.default_dist(), lambda: _duckiebot_field("centre"),
                        "inverts the Duckiebot lens inside the central circle (r_d < 1)",
                        "start from x = x_d and iterate; stop on the residual |distort(x) - x_d|, not on a count"),
        _case_undistort(dt.default_dist(), lambda: _duckiebot_field("corners"),
                        "inverts the Duckiebot lens at the four image corners",
                        "the plain fixed-point update x <- (x_d - tangential(x)) / radial(x) stalls about 0.05 "
                        "(~15 px) off at the far corners of this wide lens: it is not a contraction there. "
                        "Newton's method with the 2x2 Jacobian of the distortion converges everywhere."),
    ])


# --------------------------------------------------------------------------- rectification_maps
def _case_maps(K, dist, new_K, size, title, hint) -> Case:
    def run(fn):
        w, h = size
        out = fn(np.array(K, dtype=np.float64), np.array(dist, dtype=np.float64),
                 np.array(new_K, dtype=np.float64), (w, h))
        try:
            map_x, map_y = out
        except Exception:
            raise CheckFailed(f"should return a pair (map_x, map_y), got {type(out).__name__}",
                              hint=PAIR_HINT) from None
        for name, m in (("map_x", map_x), ("map_y", map_y)):
            if not isinstance(m, np.ndarray):
                raise CheckFailed(f"{name} should be a numpy array, got {type(m).__name__}", hint=PAIR_HINT)
            if m.shape != (h, w):
                raise CheckFailed(
                    f"{name} should have shape (height, width) = ({h}, {w}) for size = (width, height) = "
                    f"({w}, {h}), got {m.shape}", hint=SHAPE_HINT
                )
            if m.dtype != np.float32:
                raise CheckFailed(f"{name} should be float32 (what cv2.remap wants), got {m.dtype}",
                                  hint="convert at the end: map_x.astype(np.float32)")
        ref_x, ref_y = cv2.initUndistortRectifyMap(K, dist, None, new_K, (w, h), cv2.CV_32FC1)
        expect_close(map_x, ref_x, 0.01, "map_x (vs cv2.initUndistortRectifyMap)")
        expect_close(map_y, ref_y, 0.01, "map_y (vs cv2.initUndistortRectifyMap)")

    return Case(title, run, hint=hint)


#: the hint for maps of the wrong shape: size is (width, height), arrays are (rows, columns)
SHAPE_HINT = ("size is (width, height) but arrays are (height, width): w, h = size; build the grid with "
              "np.meshgrid(np.arange(w), np.arange(h)) (it returns (h, w) arrays) and reshape results to (h, w)")
PAIR_HINT = "return two numpy arrays: return map_x, map_y"


def check_rectification_maps(fn: Callable) -> Report:
    """Check ``rectification_maps(K, dist, new_K, size) -> (map_x, map_y)`` against
    ``cv2.initUndistortRectifyMap`` (within 0.01 px)."""
    K, d, size = dt.default_K(), dt.default_dist(), dt.IMAGE_SIZE
    K2 = intrinsic_matrix(180.0, 176.0, 161.0, 98.0)
    return run_check("rectification_maps", fn, [
        _case_maps(K, np.zeros(5), K, size, "no distortion and new_K = K gives the identity map",
                   "map_x[v, u] = u and map_y[v, u] = v when nothing changes; build the pixel grid with "
                   "np.meshgrid(np.arange(width), np.arange(height))"),
        _case_maps(K2, DIST_TANGENTIAL, K2, (320, 200), "a 320x200 lens with tangential terms (new_K = K)",
                   "arrays are (height, width): map_x[v, u] holds the SOURCE x coordinate for rectified pixel "
                   "(u, v). Go rectified pixel -> normalized (new_K^-1) -> distort -> pixel (K)."),
        _case_maps(K, d, new_camera_matrix(K, d, size, 0.0), size,
                   "the Duckiebot with ROS's new camera matrix (alpha = 0)",
                   "back-project with new_K (the rectified camera), but distort and project with K "
                   "(the real camera)"),
        _case_maps(K, d, new_camera_matrix(K, d, size, 1.0), size,
                   "the Duckiebot with alpha = 1 (every source pixel kept)",
                   "the rectified camera's new_K differs from K: use new_K to back-project"),
    ])
