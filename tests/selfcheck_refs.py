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
    return cv2.perspectiveTransform(np.asarray(uv, float).reshape(-1, 1, 2), np.asarray(H, float)).reshape(-1, 2)


def p2g_transposed(H, uv):
    return ref_p2g(np.asarray(H).T, uv)


def p2g_no_divide(H, uv):
    uv = np.asarray(uv, float)
    return (np.column_stack([uv, np.ones(len(uv))]) @ np.asarray(H).T)[:, :2]
