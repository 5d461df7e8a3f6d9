"""Self-checks for notebook 03, intrinsic calibration (Zhang's closed form, eqs. (5)-(13)).

Each check runs the student's function on synthetic views of the Duckietown board whose
poses and intrinsics are known exactly, and compares with that ground truth (and with
OpenCV's ``solvePnP`` for the board pose). Nothing here contains the exercise solutions:
the expected values come from the camera's definition (``H = K [r1 r2 t]``), not from a
second implementation of the student's formulas.

>>> from dtscal_lib.teaching.selfcheck.zhang import check_intrinsic_constraints
>>> check_intrinsic_constraints(my_function)   # doctest: +SKIP
"""

from __future__ import annotations

from typing import Callable

import cv2
import numpy as np

from ...boards import DUCKIETOWN_BOARD
from ...poses import board_homography, random_board_pose
from ...exercise_rules import raises_problem
from .core import Case, CheckFailed, Report, expect_close, expect_shape, run_check
from .projection import K_DUCKIE, K_SKEWED

__all__ = [
    "check_intrinsic_constraints",
    "check_intrinsics_from_homographies",
    "check_extrinsics_from_homography",
    "synthetic_views",
    "b_vector",
]

# the test cameras K_SKEWED (visible skew: catches code assuming s = 0) and K_DUCKIE (none, as real
# calibrations) are defined once, in projection.py, for every self-check


# --------------------------------------------------------------------------- ground truth
def synthetic_views(K: np.ndarray, n: int, seed: int, *, max_tilt_deg: float = 40.0,
                    distance: tuple[float, float] = (0.35, 0.7)) -> tuple[list, list, list]:
    """Board poses in front of a camera and their exact homographies.

    Parameters
    ----------
    K : (3, 3) intrinsic matrix
    n : number of views
    seed : random seed (the views are deterministic)
    max_tilt_deg : largest tilt of the board away from fronto-parallel
    distance : range of the board centre's distance from the camera (metres)

    Returns
    -------
    Hs : list of (3, 3) homographies, board metres (X, Y) -> pixels, ``H = K [r1 r2 t]``
        scaled so that ``H[2, 2] = 1``
    Rs : list of (3, 3) rotations, board -> camera
    ts : list of (3,) translations (metres), board -> camera
    """
    rng = np.random.default_rng(seed)
    Hs, Rs, ts = [], [], []
    for _ in range(n):  # tilted mostly about axes in the image plane
        R, t = random_board_pose(rng, DUCKIETOWN_BOARD, tilt_deg=(12.0, max_tilt_deg), distance=distance,
                                 spread=(0.25, 0.2), axis_z=0.3)
        Hs.append(board_homography(K, R, t))
        Rs.append(R)
        ts.append(t)
    return Hs, Rs, ts


def b_vector(K: np.ndarray) -> np.ndarray:
    """``b = (B11, B12, B22, B13, B23, B33)`` of ``B = K^-T K^-1``, (6,) float64."""
    Ki = np.linalg.inv(np.asarray(K, dtype=np.float64))
    B = Ki.T @ Ki
    return np.array([B[0, 0], B[0, 1], B[1, 1], B[0, 2], B[1, 2], B[2, 2]])


def _sym_from_b(b: np.ndarray) -> np.ndarray:
    return np.array([[b[0], b[1], b[3]], [b[1], b[2], b[4]], [b[3], b[4], b[5]]])


# --------------------------------------------------------------------------- intrinsic_constraints
def _case_constraints_property(seed: int, title: str) -> Case:
    def run(fn):
        rng = np.random.default_rng(seed)
        H = rng.normal(size=(3, 3)) * np.array([[300.0, 300.0, 300.0], [300.0, 300.0, 300.0], [1.0, 1.0, 1.0]])
        b = rng.normal(size=6)
        B = _sym_from_b(b)
        h1, h2 = H[:, 0], H[:, 1]
        want = np.array([h1 @ B @ h2, h1 @ B @ h1 - h2 @ B @ h2])
        V = expect_shape(fn(H.copy()), (2, 6), "intrinsic_constraints(H)")
        scale = np.abs(H[:, :2]).max() ** 2 * np.abs(b).max()
        got = V @ b
        if abs(got[0] - want[0]) > 1e-9 * scale:
            raise CheckFailed(
                f"row 0 dotted with b should equal h1^T B h2 = {want[0]:.6g}, got {got[0]:.6g}"
            )
        if abs(got[1] - want[1]) > 1e-9 * scale:
            raise CheckFailed(
                f"row 1 dotted with b should equal h1^T B h1 - h2^T B h2 = {want[1]:.6g}, got {got[1]:.6g}"
            )

    return Case(title, run, hint=(
        "h1, h2 are the COLUMNS of H (H[:, 0], H[:, 1]), not its rows. Write v_ij so that "
        "v_ij . b = h_i^T B h_j with b = (B11, B12, B22, B13, B23, B33): the off-diagonal "
        "entries of B appear twice, so e.g. the B12 term is h_i1 h_j2 + h_i2 h_j1. "
        "Row 0 is v12 (eq. 12), row 1 is v11 - v22 (eq. 13)."
    ))


def _case_constraints_true_K() -> Case:
    def run(fn):
        Hs, _, _ = synthetic_views(K_SKEWED, 3, seed=31)
        b = b_vector(K_SKEWED)
        for i, H in enumerate(Hs):
            V = expect_shape(fn(H.copy()), (2, 6), "intrinsic_constraints(H)")
            r = V @ b
            size = np.linalg.norm(V, axis=1) * np.linalg.norm(b)
            if np.any(np.abs(r) > 1e-9 * np.maximum(size, 1e-300)):
                raise CheckFailed(
                    f"view {i}: V @ b for the TRUE camera should be (0, 0) (eqs. 12-13 hold for the "
                    f"camera that made H), got {r}"
                )

    return Case("the true camera satisfies both constraints on exact homographies", run, hint=(
        "eq. (12) says h1^T B h2 = 0 and eq. (13) says h1^T B h1 = h2^T B h2 for the real K."
    ))


def check_intrinsic_constraints(fn: Callable) -> Report:
    """Check ``intrinsic_constraints(H) -> (2, 6)`` (rows ``v12`` and ``v11 - v22``).

    The rows are tested by what they mean: for ANY symmetric ``B`` with entries ``b``,
    ``V @ b`` must equal ``(h1^T B h2, h1^T B h1 - h2^T B h2)``; and for the camera that
    produced ``H``, ``V @ b = 0``.
    """
    return run_check("intrinsic_constraints", fn, [
        _case_constraints_property(3, "row 0 is v12 and row 1 is v11 - v22 (random H, random symmetric B)"),
        _case_constraints_property(4, "same on another random H"),
        _case_constraints_true_K(),
    ])


# --------------------------------------------------------------------------- intrinsics_from_homographies
def _expect_K(K, K_true, rtol: float, what: str) -> np.ndarray:
    K = expect_shape(K, (3, 3), what)
    if abs(K[2, 2] - 1.0) > 1e-9 or np.any(np.abs(K[[1, 2, 2], [0, 0, 1]]) > 1e-9 * abs(K_true[0, 0])):
        raise CheckFailed(f"{what} should look like [[fx, s, cx], [0, fy, cy], [0, 0, 1]], got\n{np.round(K, 4)}")
    names = ["fx", "s", "cx", "fy", "cy"]
    idx = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2)]
    bad = []
    for name, (i, j) in zip(names, idx):
        tol = rtol * abs(K_true[0, 0]) if name == "s" else rtol * abs(K_true[i, j])
        if not abs(K[i, j] - K_true[i, j]) <= tol:
            bad.append(f"{name} = {K[i, j]:.6f} (true {K_true[i, j]:.6f})")
    if bad:
        raise CheckFailed(f"{what}: " + ", ".join(bad))
    return K


def _case_K_exact(K_true, n, seed, title, scale_seed=None) -> Case:
    def run(fn):
        Hs, _, _ = synthetic_views(K_true, n, seed=seed)
        if scale_seed is not None:
            rng = np.random.default_rng(scale_seed)
            Hs = [H * rng.choice([-1.0, 1.0]) * rng.uniform(0.01, 100.0) for H in Hs]
        _expect_K(fn([H.copy() for H in Hs]), K_true, 1e-6, "K")

    return Case(title, run, hint=(
        "stack the two rows of every view into V (2M x 6), take b as the right singular vector of V "
        "with the smallest singular value, then recover fx, fy, cx, cy and s from B = K^-T K^-1 "
        "(Zhang's closed form, or a Cholesky factorisation of B). B is only known up to scale AND "
        "sign: make it positive definite (flip b if B11 < 0) before taking square roots."
    ))


def _case_K_opencv_homographies() -> Case:
    def run(fn):
        _, Rs, ts = synthetic_views(K_DUCKIE, 6, seed=33)
        obj = DUCKIETOWN_BOARD.object_points()
        Hs = []
        for R, t in zip(Rs, ts):
            img = (obj @ R.T + t) @ K_DUCKIE.T
            img = img[:, :2] / img[:, 2:]
            H, _ = cv2.findHomography(obj[:, :2], img, 0)
            Hs.append(H)
        _expect_K(fn(Hs), K_DUCKIE, 1e-6, "K")

    return Case("recovers a zero-skew Duckiebot K from OpenCV's findHomography (6 views)", run, hint=(
        "the homographies here come from cv2.findHomography (H[2, 2] = 1); "
        "the result should have s close to 0 without forcing it."
    ))


def _case_K_too_few() -> Case:
    def run(fn):
        for n in (2, 1):  # the grader asks both
            Hs, _, _ = synthetic_views(K_SKEWED, n, seed=34)
            try:
                K = fn([H.copy() for H in Hs])
            except NotImplementedError:
                raise
            except ValueError as exc:
                why = raises_problem(f"ValueError: {exc}")
                if why:
                    raise CheckFailed(why) from None
                continue
            raise CheckFailed(
                f"with only {n} view(s) the 5 unknowns of K are not determined, but the function returned\n"
                f"{np.round(np.asarray(K, dtype=float), 3)}"
            )

    return Case("refuses fewer than 3 views with a ValueError", run, hint=(
        "each view gives 2 equations and b has 6 entries defined up to scale (5 unknowns): "
        "check len(Hs) >= 3 first and `raise ValueError(\"need at least 3 views ...\")`."
    ))


def check_intrinsics_from_homographies(fn: Callable) -> Report:
    """Check ``intrinsics_from_homographies(Hs) -> K`` (3, 3), closed form with skew.

    Noise-free homographies of known cameras must give ``K`` within 1e-6 relative; the
    homographies' arbitrary scale and sign must not matter; fewer than 3 views must raise
    ``ValueError``.
    """
    return run_check("intrinsics_from_homographies", fn, [
        _case_K_exact(K_SKEWED, 3, 41, "recovers K with skew from 3 exact views"),
        _case_K_exact(K_SKEWED, 12, 42, "recovers K from 12 views given with random scale and sign",
                      scale_seed=43),
        _case_K_opencv_homographies(),
        _case_K_too_few(),
    ])


# --------------------------------------------------------------------------- extrinsics_from_homography
def _call_extrinsics(fn, K, H):
    out = fn(np.array(K, dtype=np.float64), np.array(H, dtype=np.float64))
    try:
        R, t = out
    except Exception:
        raise CheckFailed(f"should return a pair (R, t), got {type(out).__name__}") from None
    R = expect_shape(R, (3, 3), "R")
    t = np.asarray(t, dtype=np.float64)
    if t.size != 3:
        raise CheckFailed(f"t should have 3 entries, got shape {t.shape}")
    return R, expect_shape(t.reshape(3), (3,), "t")


def _expect_rotation(R, what="R"):
    orth = np.abs(R.T @ R - np.eye(3)).max()
    if orth > 1e-9:
        raise CheckFailed(
            f"{what} is not orthonormal (|R^T R - I| up to {orth:.2g}): with real (noisy) "
            "homographies r1 and r2 are not exactly orthonormal"
        )
    det = np.linalg.det(R)
    if det < 0:
        raise CheckFailed(f"det({what}) = {det:.3f}: this is a reflection, not a rotation")


def _case_pose_exact(K, seed, title, sign=1.0) -> Case:
    def run(fn):
        Hs, Rs, ts = synthetic_views(K, 4, seed=seed)
        for i, (H, R_true, t_true) in enumerate(zip(Hs, Rs, ts)):
            R, t = _call_extrinsics(fn, K, sign * 3.7 * H)
            if t[2] <= 0:
                raise CheckFailed(f"view {i}: t_z = {t[2]:.4f} puts the board BEHIND the camera")
            _expect_rotation(R)
            expect_close(R, R_true, 1e-8, f"view {i}: R")
            expect_close(t, t_true, 1e-8, f"view {i}: t (metres)")

    hint = (
        "lambda = 1 / ||K^-1 h1||; r1 = lambda K^-1 h1, r2 = lambda K^-1 h2, r3 = r1 x r2, "
        "t = lambda K^-1 h3. If t_z < 0, flip the sign of lambda (the board must be in front)."
    )
    return Case(title, run, hint=hint)


def _case_pose_noisy() -> Case:
    def run(fn):
        K = K_DUCKIE
        _, Rs, ts = synthetic_views(K, 3, seed=52, max_tilt_deg=50.0)
        obj = DUCKIETOWN_BOARD.object_points()
        rng = np.random.default_rng(53)
        for i, (R_true, t_true) in enumerate(zip(Rs, ts)):
            img = (obj @ R_true.T + t_true) @ K.T
            img = img[:, :2] / img[:, 2:] + rng.normal(scale=0.2, size=(len(obj), 2))
            H, _ = cv2.findHomography(obj[:, :2], img, 0)
            R, t = _call_extrinsics(fn, K, H)
            if t[2] <= 0:
                raise CheckFailed(f"view {i}: t_z = {t[2]:.4f} puts the board BEHIND the camera")
            _expect_rotation(R)
            ok, rvec, tvec = cv2.solvePnP(obj, img, K, None, flags=cv2.SOLVEPNP_IPPE)
            R_cv = cv2.Rodrigues(rvec)[0]
            angle = np.degrees(np.arccos(np.clip((np.trace(R.T @ R_cv) - 1) / 2, -1, 1)))
            if angle > 3.0:  # the closed form is noisier than solvePnP's least squares, not this much
                raise CheckFailed(f"view {i}: R is {angle:.2f} deg away from OpenCV's solvePnP (allowed 3)")
            if np.linalg.norm(t - tvec.ravel()) > 0.03 * np.linalg.norm(tvec):
                raise CheckFailed(
                    f"view {i}: t = {np.round(t, 4)} m, OpenCV's solvePnP says {np.round(tvec.ravel(), 4)} m"
                )

    return Case("noisy homography: R is the nearest proper rotation, close to OpenCV's solvePnP", run, hint=(
        "with noise, [r1 r2 r1xr2] is not orthonormal: replace it by the nearest rotation, "
        "U @ Vt from its SVD (and if det(U @ Vt) < 0, negate the last column of U)."
    ))


def check_extrinsics_from_homography(fn: Callable) -> Report:
    """Check ``extrinsics_from_homography(K, H) -> (R, t)``.

    R must be a proper rotation (orthonormal, det +1) and the board must be in front of
    the camera (``t_z > 0``), whatever the scale and sign of ``H``; exact homographies give
    the true pose, noisy ones a pose close to OpenCV's ``solvePnP``.
    """
    return run_check("extrinsics_from_homography", fn, [
        _case_pose_exact(K_SKEWED, 61, "exact pose from exact homographies (K with skew)"),
        _case_pose_exact(K_DUCKIE, 62, "board in front of the camera even when H comes with a negative scale",
                         sign=-1.0),
        _case_pose_noisy(),
    ])
