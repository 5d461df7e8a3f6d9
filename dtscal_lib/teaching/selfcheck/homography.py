"""Self-checks for notebook 02, homographies (eqs. (3)-(6)).

``check_apply_homography(fn)`` and ``check_estimate_homography(fn)`` test a student's
functions against homographies known by construction (``H = K [r1 r2 t]`` of a board
pose, or a hand-made H) and against OpenCV (``cv2.perspectiveTransform``,
``cv2.getPerspectiveTransform``, ``cv2.findHomography`` with method 0, OpenCV's
least-squares fit).
"""

from __future__ import annotations

from typing import Callable

import cv2
import numpy as np

from ...boards import DUCKIETOWN_BOARD
from ...mistakes import raw_dlt
from ...poses import board_homography, random_board_pose
from .core import Case, CheckFailed, Report, expect_close, expect_shape, num, run_check
from .projection import K_DUCKIE

__all__ = [
    "check_apply_homography",
    "check_estimate_homography",
    "board_homography",
    "transfer_rms",
    "NOISY_TOLERANCE",
]

#: a student's fit on noisy points may have at most this much more transfer error than OpenCV's
NOISY_TOLERANCE = 0.01


def _opencv_apply(H, pts) -> np.ndarray:
    return cv2.perspectiveTransform(np.asarray(pts, np.float64).reshape(-1, 1, 2), np.asarray(H, np.float64)).reshape(-1, 2)


def transfer_rms(H: np.ndarray, src: np.ndarray, dst: np.ndarray) -> float:
    """RMS distance (in dst units) between ``H`` applied to ``src`` (N, 2) and ``dst`` (N, 2)."""
    return float(np.sqrt(np.mean(np.sum((_opencv_apply(H, src) - dst) ** 2, axis=1))))


# --------------------------------------------------------------------------- apply_homography
def _apply(fn, H, pts):
    H_in, p_in = np.array(H, dtype=np.float64), np.array(pts, dtype=np.float64)
    out = expect_shape(fn(H_in, p_in), (len(pts), 2), "apply_homography(H, pts)")
    if not (np.array_equal(H_in, H) and np.array_equal(p_in, pts)):
        raise CheckFailed("apply_homography changed its inputs; work on copies")
    return out


def _random_H(rng) -> np.ndarray:
    R, t = random_board_pose(rng)
    return board_homography(K_DUCKIE, R, t)


def check_apply_homography(fn: Callable) -> Report:
    """Check ``apply_homography(H, pts) -> (N, 2)``: ``[u, v, w]^T = H [x, y, 1]^T``, then ``(u/w, v/w)``."""
    rng = np.random.default_rng(201)
    pts = rng.uniform(-1.0, 1.0, size=(10, 2))
    H_tr = np.array([[1.0, 0.0, 5.0], [0.0, 1.0, -3.0], [0.0, 0.0, 1.0]])
    H_proj = _random_H(rng)
    board = DUCKIETOWN_BOARD.object_points()[:, :2]

    def identity(f):
        expect_close(_apply(f, np.eye(3), pts), pts, 1e-12, "points under the identity")

    def translation(f):
        expect_close(_apply(f, H_tr, pts), pts + [5.0, -3.0], 1e-12, "points under a translation")

    def projective(f):
        expect_close(_apply(f, H_proj, board), _opencv_apply(H_proj, board), 1e-8,
                     "board corners vs cv2.perspectiveTransform")

    def scale(f):
        expect_close(_apply(f, 7.3 * H_proj, board), _opencv_apply(H_proj, board), 1e-8,
                     "points under 7.3 * H (the same homography)")

    def one_point(f):
        expect_close(_apply(f, H_proj, board[:1]), _opencv_apply(H_proj, board[:1]), 1e-8, "a single point")

    return run_check("apply_homography", fn, [
        Case("identity leaves points unchanged", identity,
             hint="append a 1 to each point: [x, y, 1], multiply by H, divide by the third coordinate"),
        Case("translation", translation, hint="points are ROWS of pts: the product is pts_h @ H.T"),
        Case("a board pose's homography agrees with cv2.perspectiveTransform", projective,
             hint="divide u and v by the third homogeneous coordinate w of each point"),
        Case("H and 7.3 * H map points alike (H is defined up to scale)", scale,
             hint="after H @ [x, y, 1] divide by the third coordinate; do not assume it is 1"),
        Case("a single point (N = 1)", one_point, hint="keep the result shape (N, 2) for N = 1"),
    ])


# --------------------------------------------------------------------------- estimate_homography
def _estimate(fn, src, dst):
    s_in, d_in = np.array(src, dtype=np.float64), np.array(dst, dtype=np.float64)
    H = expect_shape(fn(s_in, d_in), (3, 3), "estimate_homography(src, dst)")
    if not (np.array_equal(s_in, src) and np.array_equal(d_in, dst)):
        raise CheckFailed("estimate_homography changed its inputs; work on copies")
    return H


def _noisy_case(rng, n: int, sigma: float, offset: float = 0.0, span: float = 1.0):
    """Pixel -> pixel correspondences: src spread over a (scaled) image, dst = H_true src + noise."""
    src = np.column_stack([rng.uniform(40, 600, n), rng.uniform(40, 440, n)]) * span + offset
    R, t = random_board_pose(rng)
    # maps src back to board-like metres then to pixels: a generic well-conditioned homography
    A = np.array([[0.2 / (560 * span), 0, -offset * 0.2 / (560 * span)],
                  [0, 0.15 / (400 * span), -offset * 0.15 / (400 * span)], [0, 0, 1.0]])
    H_true = board_homography(K_DUCKIE, R, t) @ A
    H_true /= H_true[2, 2]
    dst = _opencv_apply(H_true, src) + rng.normal(0.0, sigma, size=(n, 2))
    return src, dst, H_true


def _evidence(H, src, dst) -> str:
    """What the answer shows about the cause, or '' (a hint never names a cause the answer does not show)."""
    raw = raw_dlt(src, dst)
    if np.allclose(H / H[2, 2], raw, rtol=1e-4, atol=1e-9 * np.abs(raw).max()):
        return ("; your H equals the DLT WITHOUT normalization: centre and scale both point sets first "
                "(Hartley), then undo it as H = inv(T_dst) @ H_n @ T_src")
    return ""


def check_estimate_homography(fn: Callable) -> Report:
    """Check ``estimate_homography(src, dst) -> (3, 3)``: normalized DLT, ``H[2, 2] = 1``, maps src to dst."""
    rng = np.random.default_rng(202)
    sq_src = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    sq_dst = np.array([[102.0, 80.0], [415.0, 95.0], [460.0, 390.0], [90.0, 350.0]])
    board = DUCKIETOWN_BOARD.object_points()[:, :2]
    R, t = random_board_pose(rng)
    H_board = board_homography(K_DUCKIE, R, t)
    noisy = [_noisy_case(rng, 35, 0.5) for _ in range(3)]
    big = _noisy_case(rng, 35, 1.0, offset=1.0e4)
    far_src, far_dst, _ = _noisy_case(rng, 35, 0.0, offset=1.0e5)

    def four_points(f):
        H = _estimate(f, sq_src, sq_dst)
        want = cv2.getPerspectiveTransform(sq_src.astype(np.float32), sq_dst.astype(np.float32)).astype(np.float64)
        expect_close(_opencv_apply(H, sq_src), sq_dst, 1e-6, "H applied to the 4 source points (pixels)")
        expect_close(H / H[2, 2], want / want[2, 2], 1e-6, "H vs cv2.getPerspectiveTransform", rtol=1e-6)

    def scaled(f):
        H = _estimate(f, sq_src, sq_dst)
        if abs(H[2, 2] - 1.0) > 1e-9:
            raise CheckFailed(f"H[2, 2] should be 1, got {num(H[2, 2])}")

    def exact_board(f):
        dst = _opencv_apply(H_board, board)
        H = _estimate(f, board, dst)
        expect_close(_opencv_apply(H, board), dst, 1e-8, "noise-free board corners mapped by your H (pixels)")
        expect_close(H, H_board, 1e-8, "H vs the true homography K [r1 r2 t]", rtol=1e-7)

    def noisy_fit(f):
        for i, (src, dst, _) in enumerate(noisy):
            H = _estimate(f, src, dst)
            mine = transfer_rms(H, src, dst)
            ref = transfer_rms(cv2.findHomography(src, dst, 0)[0], src, dst)
            if not mine <= ref * (1 + NOISY_TOLERANCE) + 1e-9:
                raise CheckFailed(f"case {i}: transfer error {mine:.4f} px; OpenCV's least-squares fit "
                                  f"reaches {ref:.4f} px (allowed {100 * NOISY_TOLERANCE:g} % more)"
                                  + _evidence(H, src, dst))

    def big_coordinates(f):
        src, dst, _ = big
        H = _estimate(f, src, dst)
        mine = transfer_rms(H, src, dst)
        ref = transfer_rms(cv2.findHomography(src, dst, 0)[0], src, dst)
        if not mine <= ref * (1 + NOISY_TOLERANCE) + 1e-9:
            raise CheckFailed(f"source coordinates near 10000: transfer error {mine:.4f} px vs OpenCV's "
                              f"{ref:.4f} px" + _evidence(H, src, dst))

    def far_exact(f):
        H = _estimate(f, far_src, far_dst)
        try:
            expect_close(_opencv_apply(H, far_src), far_dst, 1e-8, "noise-free points near 100000 mapped by your H")
        except CheckFailed as exc:
            raise CheckFailed(str(exc) + _evidence(H, far_src, far_dst)) from None

    return run_check("estimate_homography", fn, [
        Case("4 exact correspondences agree with cv2.getPerspectiveTransform", four_points,
             hint="2 rows per correspondence in A (eq. (6) cross-multiplied); h = last right singular vector "
                  "of A (np.linalg.svd(A)[2][-1]), reshaped to 3x3"),
        Case("H[2, 2] = 1", scaled, hint="H is defined up to scale: divide by H[2, 2] at the end"),
        Case("noise-free Duckietown board: H = K [r1 r2 t] (eq. (5)-(6))", exact_board,
             hint="check the direction: H must map src to dst; if you normalized the points, undo it as "
                  "H = inv(T_dst) @ H_n @ T_src"),
        Case("noisy pixels (0.5 px): within 1 % of OpenCV's least-squares fit", noisy_fit,
             hint="the normalized DLT uses all N correspondences (2 rows of A each) and h = the right singular "
                  "vector of A's smallest singular value (eqs. (3)-(6))"),
        Case("noisy points far from the origin (near 10000): still within 1 % of OpenCV", big_coordinates,
             hint="coordinates near 10000 test the conditioning of A: the normalized DLT (eqs. (3)-(6)) keeps "
                  "its columns comparable"),
        Case("noise-free points near 100000: mapped within 1e-8", far_exact,
             hint="coordinates near 100000 test the conditioning of A: the normalized DLT (eqs. (3)-(6)) keeps "
                  "its columns comparable"),
    ])
