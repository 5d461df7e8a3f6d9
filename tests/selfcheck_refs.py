"""Reference and typical-mistake implementations of course exercises, shared by the self-check tests
(test_selfcheck_course, test_course): written here independently of the solution notebooks and of the
library's own functions (OpenCV, or another derivation), plus a stub and a quiet runner of a check."""

from __future__ import annotations

import cv2
import numpy as np


def stub(*args, **kwargs):
    raise NotImplementedError("write this function")


def status(check, fn):
    return _quiet(check, fn).status


def _quiet(check, fn):
    import contextlib
    import io

    with contextlib.redirect_stdout(io.StringIO()):
        return check(fn)


def ref_constraints(H):
    """v_ij built from the quadratic form h_i^T B h_j, by differentiating with respect to b."""
    H = np.asarray(H, dtype=float)
    basis = []
    for k in range(6):
        e = np.zeros(6)
        e[k] = 1.0
        B = np.array([[e[0], e[1], e[3]], [e[1], e[2], e[4]], [e[3], e[4], e[5]]])
        basis.append(B)
    h1, h2 = H[:, 0], H[:, 1]
    v12 = [h1 @ B @ h2 for B in basis]
    d = [h1 @ B @ h1 - h2 @ B @ h2 for B in basis]
    return np.array([v12, d])


def ref_intrinsics(Hs):
    """Closed form via a Cholesky factorisation of B (not Zhang's explicit formulas)."""
    if len(Hs) < 3:
        raise ValueError("need at least 3 views")
    V = np.vstack([ref_constraints(H / np.linalg.norm(H)) for H in Hs])
    b = np.linalg.svd(V)[2][-1]
    B = np.array([[b[0], b[1], b[3]], [b[1], b[2], b[4]], [b[3], b[4], b[5]]])
    if B[0, 0] < 0:
        B = -B
    L = np.linalg.cholesky(B)  # B = L L^T = K^-T K^-1  ->  K^-1 = L^T (up to scale)
    K = np.linalg.inv(L.T)
    return K / K[2, 2]


def ref_p2g(H, uv):
    """pixel -> ground, the homogeneous division written out entry by entry (OpenCV's perspectiveTransform would
    be refused by the self-check: it computes the exercise; tests/test_selfcheck_course compares the two)."""
    H, uv = np.asarray(H, float), np.asarray(uv, float).reshape(-1, 2)
    u, v = uv[:, 0], uv[:, 1]
    w = H[2, 0] * u + H[2, 1] * v + H[2, 2]
    return np.column_stack([(H[0, 0] * u + H[0, 1] * v + H[0, 2]) / w, (H[1, 0] * u + H[1, 1] * v + H[1, 2]) / w])


def cv2_p2g(H, uv):
    """OpenCV's routine, which computes the exercise: a forbidden shortcut (refused by the self-check and the
    grader alike)."""
    return cv2.perspectiveTransform(np.asarray(uv, float).reshape(-1, 1, 2), np.asarray(H, float)).reshape(-1, 2)


def p2g_transposed(H, uv):
    return ref_p2g(np.asarray(H).T, uv)


def p2g_no_divide(H, uv):
    uv = np.asarray(uv, float)
    return (np.column_stack([uv, np.ones(len(uv))]) @ np.asarray(H).T)[:, :2]


# --------------------------------------------------------------------------- notebook 04, written out
# A student's function may not call the kit's library (dtscal_lib.camera) nor OpenCV's solving routines: the
# self-check refuses them as the grader does (dtscal_lib/exercise_rules.py). These are the plumb_bob model, its
# Newton inverse and the rectification maps written out here, as a student writes them.
def np_distort(xy, dist):
    """plumb_bob (OpenCV's order k1, k2, p1, p2, k3) by its polynomial."""
    xy = np.asarray(xy, float).reshape(-1, 2)
    k1, k2, p1, p2, k3 = np.ravel(np.asarray(dist, float))[:5]
    x, y = xy.T
    rr = x * x + y * y
    g = 1.0 + rr * (k1 + rr * (k2 + rr * k3))
    return np.stack([g * x + 2.0 * p1 * x * y + p2 * (rr + 2.0 * x * x),
                     g * y + p1 * (rr + 2.0 * y * y) + 2.0 * p2 * x * y], axis=1)


def np_undistort(xy_d, dist, steps=60):
    """Newton's method on distort(x) = x_d, with a central-difference Jacobian per point."""
    target = np.asarray(xy_d, float).reshape(-1, 2)
    xy, h = target.copy(), 1e-7
    for _ in range(steps):
        r = np_distort(xy, dist) - target
        if np.abs(r).max(initial=0.0) < 1e-15:
            break
        cols = [(np_distort(xy + h * e, dist) - np_distort(xy - h * e, dist)) / (2 * h) for e in np.eye(2)]
        J = np.stack(cols, axis=2)  # J[n, i, j] = d distort_i / d x_j
        xy = xy - np.linalg.solve(J, r[..., None])[..., 0]
    return xy


def np_maps(K, dist, new_K, size, dtype=np.float32):
    """Rectified pixel -> new_K^-1 -> distort -> K, as (height, width) maps."""
    w, h = int(size[0]), int(size[1])
    v, u = np.mgrid[0:h, 0:w].astype(float)
    rays = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], axis=1) @ np.linalg.inv(np.asarray(new_K, float)).T
    src = np.column_stack([np_distort(rays[:, :2] / rays[:, 2:], dist), np.ones(u.size)]) @ np.asarray(K, float).T
    return src[:, 0].reshape(h, w).astype(dtype), src[:, 1].reshape(h, w).astype(dtype)
