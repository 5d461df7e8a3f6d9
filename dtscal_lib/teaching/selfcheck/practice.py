"""Self-checks of the practice functions: what a student writes for their own analysis (never graded).

Notebooks 01, 03b and 06 ask for a function or two of the student's own (cells tagged ``practice``,
see :mod:`dtscal_lib.teaching.release`). Each is checked here like an exercise, against answers
computed independently: OpenCV's ``projectPoints`` for the pictures of notebook 01, sums written out
for the per-view RMS of 03b, and ROS's rule (``camera_calibration/calibrator.py``: X and Y are where the
board has been, Size how close, Skew how tilted) for notebook 06's next board move.
"""

from __future__ import annotations

from typing import Callable

import cv2
import numpy as np

from ... import duckietown as dt
from ...boards import DUCKIETOWN_BOARD
from ...coverage import Bar
from ...poses import look_at_pose
from .core import Case, CheckFailed, Report, expect_close, run_check

__all__ = ["check_picture_difference", "check_tilt_needed", "check_per_view_rms", "check_worst_views",
           "check_coverage", "check_next_board_move", "MOVES"]


# --------------------------------------------------------------------------- notebook 01
def _cv_picture(K, pose) -> np.ndarray:
    R, t = pose
    uv, _ = cv2.projectPoints(DUCKIETOWN_BOARD.object_points(), cv2.Rodrigues(np.asarray(R, float))[0],
                              np.asarray(t, float), np.asarray(K, float), None)
    return uv.reshape(-1, 2)


def _cv_difference(K_a, pose_a, K_b, pose_b) -> float:
    return float(np.sqrt(((_cv_picture(K_a, pose_a) - _cv_picture(K_b, pose_b)) ** 2).sum(axis=1)).max())


def _twice_f(K) -> np.ndarray:
    K2 = np.array(K, dtype=float)
    K2[0, 0] *= 2
    K2[1, 1] *= 2
    return K2


def check_picture_difference(fn: Callable) -> Report:
    """Check ``picture_difference(K_a, pose_a, K_b, pose_b) -> float`` against OpenCV's projections."""
    K = dt.default_K()

    def case(K_a, pose_a, K_b, pose_b):
        def run(f):
            got = f(K_a.copy(), pose_a, K_b.copy(), pose_b)
            if np.ndim(got) != 0:
                raise CheckFailed(f"should return one number (the largest distance), got shape {np.shape(got)}",
                                  hint="take the largest of the per-corner distances: .max() of the norms")
            expect_close(float(got), _cv_difference(K_a, pose_a, K_b, pose_b), 1e-6, "the largest distance (px)")
        return run

    moved = K.copy()
    moved[0, 2] += 3.0
    moved[1, 2] += 4.0
    tilted = look_at_pose(yaw_deg=30, distance=0.4)
    return run_check("picture_difference", fn, graded=False, cases=[
        Case("the same camera twice: 0 px", case(K, look_at_pose(distance=0.4), K, look_at_pose(distance=0.4)),
             hint="project the board's corners (board.object_points()) with both cameras and compare them"),
        Case("principal point moved by (3, 4) px: 5 px", case(K, tilted, moved, tilted),
             hint="the distance of two pixels is the Euclidean norm of their difference, sqrt(du^2 + dv^2)"),
        Case("f at 0.4 m against 2f at 0.8 m, tilted 30 deg (vs cv2.projectPoints)",
             case(K, tilted, _twice_f(K), look_at_pose(yaw_deg=30, distance=0.8)),
             hint="use each camera's own K and pose: project(K_a, *pose_a, X) and project(K_b, *pose_b, X)"),
    ])


def _cv_tilt_needed(threshold_px: float, tilts) -> int | None:
    K = dt.default_K()
    for tilt in tilts:
        if _cv_difference(K, look_at_pose(yaw_deg=tilt, distance=0.4),
                          _twice_f(K), look_at_pose(yaw_deg=tilt, distance=0.8)) > threshold_px:
            return tilt
    return None


def check_tilt_needed(fn: Callable) -> Report:
    """Check ``tilt_needed(threshold_px, tilts) -> int or None`` against the same search with OpenCV's projections."""
    def case(threshold, tilts):
        def run(f):
            want = _cv_tilt_needed(threshold, tilts)
            got = f(threshold, tilts)
            if got != want:
                raise CheckFailed(f"tilt_needed({threshold}, {tilts!r}) returned {got!r}, expected {want!r}")
        return run

    return run_check("tilt_needed", fn, graded=False, cases=[
        Case("1 px over tilts 0 to 60 deg", case(1.0, range(0, 61)),
             hint="go through the tilts in order and return the FIRST whose difference is larger than the threshold"),
        Case("3 px over every 5th degree", case(3.0, range(0, 61, 5)),
             hint="use the tilts you are given (the second argument), not a range of your own"),
        Case("1000 px is never reached: None", case(1000.0, range(0, 61, 10)),
             hint="when no tilt differs by more than the threshold, return None after the loop"),
    ])


# --------------------------------------------------------------------------- notebook 03b
def _residual_set() -> list[np.ndarray]:
    rng = np.random.default_rng(3)
    return [rng.normal(0, s, (n, 2)) for s, n in ((0.1, 35), (2.0, 35), (0.5, 12))]


def check_per_view_rms(fn: Callable) -> Report:
    """Check ``per_view_rms(residuals) -> (M,)``: sqrt of the mean squared residual length, per view."""
    def run_values(f):
        res = _residual_set()
        want = [float(np.sqrt(sum(float(u * u + v * v) for u, v in r) / len(r))) for r in res]
        got = np.asarray(f([r.copy() for r in res]), dtype=float)
        if got.shape != (3,):
            raise CheckFailed(f"should return one RMS per view, shape (3,) for 3 views, got {got.shape}",
                              hint="loop over the views (or use a list comprehension) and return np.array([...])")
        if np.allclose(got, np.array(want) / np.sqrt(2), rtol=1e-9):
            raise CheckFailed("got the RMS per COORDINATE (1/sqrt(2) of the answer)",
                              hint="square the LENGTH of each residual vector (du^2 + dv^2), then average over the "
                                   "corners, not over corners and coordinates")
        expect_close(got, want, 1e-9, "per-view RMS (px)")

    def run_one(f):
        got = np.asarray(f([np.array([[3.0, 4.0]])]), dtype=float)
        expect_close(got.ravel(), [5.0], 1e-12, "RMS of one corner off by (3, 4) px")

    return run_check("per_view_rms", fn, graded=False, cases=[
        Case("three views with different noise", run_values,
             hint="RMS of a view = sqrt(mean over its corners of du^2 + dv^2)"),
        Case("one view of one corner off by (3, 4): 5 px", run_one,
             hint="the length of (3, 4) is 5: sqrt(3^2 + 4^2)"),
    ])


def check_worst_views(fn: Callable) -> Report:
    """Check ``worst_views(rms, n) -> list of n view indices``, worst first."""
    rms = np.array([0.3, 5.0, 0.1, 2.0, 7.5])

    def case(n, want):
        def run(f):
            got = [int(i) for i in f(rms.copy(), n)]
            if got != want:
                raise CheckFailed(f"worst_views({rms.tolist()}, {n}) returned {got}, expected {want}")
        return run

    return run_check("worst_views", fn, graded=False, cases=[
        Case("the 3 worst of 5 views, worst first", case(3, [4, 1, 3]),
             hint="np.argsort sorts ascending: reverse it ([::-1]) for the worst first, then keep n"),
        Case("n = 1", case(1, [4]), hint="return a list (or array) of n indices, even for n = 1"),
    ])


def check_coverage(fn: Callable) -> Report:
    """Check ``coverage(errors, sigmas, k) -> float``: the fraction of ``|error| <= k sigma``, over every entry."""
    errors = np.array([[0.5, -2.0], [1.5, -0.2], [-3.0, 0.9]])
    sigmas = np.array([[1.0, 1.0], [1.0, 0.5], [1.0, 1.0]])

    def case(k, want):
        def run(f):
            got = f(errors.copy(), sigmas.copy(), k)
            if np.ndim(got) != 0:
                raise CheckFailed(f"should return one fraction, got shape {np.shape(got)}",
                                  hint="average over every entry (all trials and all parameters): np.mean(...)")
            if abs(float(got) - want) > 1e-12 and abs(float(got) - 100 * want) < 1e-9:
                raise CheckFailed(f"got {got}, a percentage; expected the fraction {want}",
                                  hint="return a fraction between 0 and 1, not a percentage")
            mistakes = {float(np.mean(errors <= k * sigmas)): ABS_HINT, float(np.mean(np.abs(errors) <= sigmas)): K_HINT}
            if abs(float(got) - want) > 1e-12:
                hint = next((h for v, h in mistakes.items() if abs(float(got) - v) < 1e-12 and abs(v - want) > 1e-12),
                            None)
                raise CheckFailed(f"coverage at k = {k}: got {float(got):.4g}, expected {want:.4g}", hint=hint)
        return run

    return run_check("coverage", fn, graded=False, cases=[
        Case("1 sigma: 3 of 6 errors", case(1.0, 0.5), hint="count the entries with |error| <= k * sigma, divide by "
             "how many there are"),
        Case("2 sigma: 5 of 6 errors", case(2.0, 5 / 6), hint="count the entries with |error| <= k * sigma"),
    ])


ABS_HINT = "an error counts when |error| <= k * sigma: take the absolute value, errors can be negative"
K_HINT = "use k: the bound is k * sigma, not sigma"


# --------------------------------------------------------------------------- notebook 06
#: what to do with the board for each bar, ROS's meaning of it (camera_calibration/calibrator.py)
MOVES = {"X": ("left", "right"), "Y": ("up", "down"), "Size": ("closer",), "Skew": ("tilt",)}


def _bars(values) -> list[Bar]:
    ranges = dict(zip(("X", "Y", "Size", "Skew"), (0.7, 0.7, 0.4, 0.5)))
    out = []
    for name, (lo, hi) in zip(("X", "Y", "Size", "Skew"), values):
        progress = min(1.0, (hi - lo) / ranges[name])
        out.append(Bar(name, lo, hi, progress, progress >= 1.0))
    return out


def check_next_board_move(fn: Callable) -> Report:
    """Check ``next_board_move(bars) -> str``: the move that fills the emptiest bar, as ROS's bars define them.

    X and Y are where the board has been (0 = left / top, 1 = right / bottom): go where it has not been, the
    side farther from the range seen. Size fills as the board comes closer, Skew as it is tilted.
    """
    def case(values, want):
        def run(f):
            got = f(_bars(values))
            if got not in {m for moves in MOVES.values() for m in moves}:
                raise CheckFailed(f"returned {got!r}; answer one of 'left', 'right', 'up', 'down', 'closer', 'tilt'",
                                  hint="return the move as one of the six words, a plain string")
            if got != want:
                bars = _bars(values)
                shown = [(b.name, round(b.progress, 2)) for b in bars]
                emptiest = min(bars, key=lambda b: b.progress)
                moved = next(name for name, moves in MOVES.items() if got in moves)
                hint = None if moved == emptiest.name else (
                    f"pick the bar with the SMALLEST progress (here {emptiest.name}: {emptiest.progress:.2f}), not "
                    f"another one that is not full ({moved}: {next(b.progress for b in bars if b.name == moved):.2f})")
                raise CheckFailed(f"for bars {shown} returned {got!r}, expected {want!r}", hint=hint)
        return run

    return run_check("next_board_move", fn, graded=False, cases=[
        Case("only the right half seen: go left", case([(0.5, 0.9), (0.0, 1.0), (0.0, 0.4), (0.0, 0.5)], "left"),
             hint="X's lo and hi say where the board has been (0 = left edge, 1 = right edge): a large lo means "
                  "the left was never visited"),
        Case("the top never seen: go up", case([(0.0, 1.0), (0.4, 0.95), (0.0, 0.4), (0.0, 0.5)], "up"),
             hint="Y works like X: 0 is the top of the image"),
        Case("boards all far away: come closer", case([(0.0, 1.0), (0.0, 1.0), (0.0, 0.1), (0.0, 0.3)], "closer"),
             hint="Size fills as the board comes closer (its largest size seen so far)"),
        Case("boards never tilted: tilt", case([(0.05, 0.9), (0.1, 0.9), (0.0, 0.3), (0.0, 0.05)], "tilt"),
             hint="Skew fills as the board is tilted"),
    ])
