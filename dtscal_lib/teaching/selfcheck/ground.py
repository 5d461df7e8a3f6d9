"""Self-checks for notebook 05, extrinsic (ground) calibration.

The board's ground coordinates are checked against the closed form of the Duckietown placement
and corner order, written out here (:func:`_closed_form_ground`; never the library's own
``ground_points``, which the exercise re-implements), and ``pixel_to_ground`` against OpenCV's
``cv2.perspectiveTransform`` and the sanity values of Duckietown's shipped default homography.
"""

from __future__ import annotations

from typing import Callable

import cv2
import numpy as np

from ... import duckietown as dt
from ...mistakes import robot_ground_homography  # a camera placed by hand: the truth by construction
from .core import Case, CheckFailed, Report, expect_close, expect_shape, nums, run_check

__all__ = ["check_board_ground_points", "check_pixel_to_ground", "check_camera_height_pitch"]


# --------------------------------------------------------------------------- board_ground_points
def _closed_form_ground(cols: int, rows: int, square: float, x0: float, y0: float) -> np.ndarray:
    """Point k = (x0 + (k // cols) * square, y0 + (k % cols) * square): the near-right corner first, then to
    the left along the near row, then row by row away from the robot (x forward, y left)."""
    k = np.arange(cols * rows)
    return np.column_stack([x0 + (k // cols) * square, y0 + (k % cols) * square]).astype(np.float64)


def _case_ground(cols, rows, square, x0, y0, title, hint) -> Case:
    def run(fn):
        want = _closed_form_ground(cols, rows, square, x0, y0)
        got = expect_shape(fn(cols, rows, square, x0, y0), (cols * rows, 2),
                           f"board_ground_points({cols}, {rows}, {square}, {x0}, {y0})")
        if np.allclose(np.sort(got, axis=0), np.sort(want, axis=0), atol=1e-12) and not np.allclose(got, want, atol=1e-12):
            raise CheckFailed(
                "the right points in the wrong order: corner 0 must be the near-right corner "
                f"{nums(want[0])}, corner 1 the next one to its LEFT "
                f"{nums(want[1])}, then row by row away from the robot; got corners 0, 1 = "
                f"{nums(got[0])}, {nums(got[1])}"
            )
        expect_close(got, want, 1e-12, "ground points (metres)")

    return Case(title, run, hint=hint)


def check_board_ground_points(fn: Callable) -> Report:
    """Check ``board_ground_points(cols, rows, square, x0, y0) -> (N, 2)`` against the board geometry."""
    order_hint = (
        "x is forward, y is LEFT. Start at (x0, y0), the near-right corner; move along the near row "
        "(y increases by `square` each step, cols corners), then the next row is `square` further "
        "(x increases): point k = (x0 + (k // cols) * square, y0 + (k % cols) * square)."
    )
    return run_check("board_ground_points", fn, [
        _case_ground(7, 5, 0.031, 0.191, -0.093, "the Duckietown board (7x5, 31 mm) in its calibration place",
                     order_hint),
        _case_ground(4, 3, 0.05, 0.3, -0.2, "a 4x3 board with 50 mm squares (cols and rows not swapped)",
                     "cols run across the robot (along y), rows go away from it (along x)"),
        _case_ground(3, 6, 0.02, 0.1, 0.05, "a 3x6 board placed off-centre to the left", order_hint),
    ])


# --------------------------------------------------------------------------- pixel_to_ground
def _cv_transform(H, uv):
    return cv2.perspectiveTransform(np.asarray(uv, dtype=np.float64).reshape(-1, 1, 2), np.asarray(H, float)).reshape(-1, 2)


def _case_default_sanity() -> Case:
    def run(fn):
        H = dt.default_H()
        uv = np.array([[320.0, 479.0], [320.0, 240.0]])
        got = expect_shape(fn(H.copy(), uv.copy()), (2, 2), "pixel_to_ground(H, uv)")
        if abs(got[0, 0] - 0.117) > 0.002 or abs(got[0, 1] - 0.004) > 0.002:
            raise CheckFailed(f"pixel (320, 479) should land about (0.117, 0.004) m ahead, got {nums(got[0])}")
        if abs(got[1, 0] - 0.289) > 0.003:
            raise CheckFailed(f"pixel (320, 240) should land about x = 0.289 m ahead, got x = {got[1, 0]:.4f}")

    return Case("Duckietown's default homography: (320, 479) -> about (0.117, 0.004) m", run, hint=(
        "multiply H by the homogeneous pixel [u, v, 1] (a column), then divide by the THIRD coordinate"
    ))


def _case_vs_opencv(seed, scale, title) -> Case:
    def run(fn):
        rng = np.random.default_rng(seed)
        H = dt.default_H() @ np.array([[1, 0.05, 3], [0.02, 1, -4], [1e-5, -2e-5, 1]]) * scale
        uv = np.column_stack([rng.uniform(0, 640, 25), rng.uniform(200, 480, 25)])
        got = expect_shape(fn(H.copy(), uv.copy()), (25, 2), "pixel_to_ground(H, uv)")
        expect_close(got, _cv_transform(H, uv), 1e-9, "ground points (metres, vs cv2.perspectiveTransform)")

    return Case(title, run, hint=(
        "ground = H @ [u, v, 1]; (x, y) = ground[:2] / ground[2]. H acts on column vectors: with points as "
        "rows, use pts_h @ H.T (not pts_h @ H)"
    ))


def check_pixel_to_ground(fn: Callable) -> Report:
    """Check ``pixel_to_ground(H, uv) -> (N, 2)`` against ``cv2.perspectiveTransform``."""
    return run_check("pixel_to_ground", fn, [
        _case_default_sanity(),
        _case_vs_opencv(71, 1.0, "a perturbed homography on 25 pixels (vs OpenCV)"),
        _case_vs_opencv(72, -250.0, "the same H multiplied by -250 gives the same ground points"),
    ])


# --------------------------------------------------------------------------- camera_height_pitch
def _case_robot(height, pitch, yaw, x, scale, title, hint) -> Case:
    def run(fn):
        K = dt.default_P()[:, :3]
        H = robot_ground_homography(K, height, pitch, yaw_deg=yaw, x=x) * scale
        try:
            got = expect_shape(fn(H.copy(), K.copy()), (2,), "camera_height_pitch(H, K)")
        except CheckFailed as exc:
            raise CheckFailed(str(exc), hint=SHAPE_HINT) from None
        if abs(got[0] + height) < 1e-6 and abs(got[1] - pitch) < 1e-5:
            raise CheckFailed(f"height {got[0]:.4f} m: the camera is {height} m ABOVE the ground; the pitch is right",
                              hint=SIGN_HINT)
        expect_close(got[:1], [height], 1e-6, "height (metres above the ground)")
        expect_close(got[1:], [pitch], 1e-5, "pitch (degrees below the horizon)")

    return Case(title, run, hint=hint)


#: the hint for a result of the wrong shape or type
SHAPE_HINT = "return np.array([height_in_metres, pitch_in_degrees]) (float64, shape (2,))"
#: the hint for the other sign of lambda: it negates r1, r2 and t, so C_z = -(r3 . t) comes out negative
SIGN_HINT = ("lambda's sign picks one of two mirror solutions; the wrong one puts the camera under the ground. "
             "Choose the sign so that a ground point AHEAD of the robot, e.g. (0.3, 0), has a positive depth "
             "(third coordinate of lambda (0.3 r1 + t)); notebook 03's rule t_z > 0 does not carry over: t is the "
             "robot's origin under the wheels, which can be behind the camera")


def check_camera_height_pitch(fn: Callable) -> Report:
    """Check ``camera_height_pitch(H, K) -> array([height_m, pitch_deg])`` on cameras placed by hand."""
    return run_check("camera_height_pitch", fn, [
        _case_robot(0.125, 24.0, 0.8, 0.062, 1.0, "a camera placed by hand on a Duckiebot-sized robot", hint=(
            "M = K^-1 H^-1 = lambda [r1 r2 t]; lambda = 1 / |M[:, 0]|; R = [r1 r2 r1 x r2]; C = -R^T t; "
            "height = C[2], pitch = degrees(asin(-R[2, 2]))")),
        _case_robot(0.2, 40.0, -3.0, 0.0, -7.5, "a higher, steeper camera; H times -7.5 (any scale and sign)", hint=(
            "H is defined up to scale and sign: fix lambda's sign so that a ground point ahead of the robot, "
            "e.g. (0.3, 0), is in front of the camera (positive depth)")),
        _case_robot(0.06, -4.0, 0.0, 0.1, 1.0, "a low camera looking slightly up", hint=(
            "this camera looks 4 deg UP: the pitch below the horizon is negative (no abs()); nearly level, asin's "
            "argument is small: clip it to [-1, 1] and keep degrees")),
    ])
