# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: max_abs_svd_cholesky
# formulation: H / its largest entry, SVD of V^T V, Cholesky

import numpy as np


_I = np.array([0, 0, 1, 0, 1, 2])
_J = np.array([0, 1, 1, 2, 2, 2])


def _vij(a, b):
    sym = a[_I] * b[_J] + a[_J] * b[_I]
    return np.where(_I == _J, sym / 2, sym)


def intrinsic_constraints(H):
    H = np.asarray(H, dtype=np.float64)
    h1, h2 = H[:, 0], H[:, 1]
    return np.stack([_vij(h1, h2), _vij(h1, h1) - _vij(h2, h2)])


def intrinsics_from_homographies(Hs):
    Hs = [np.asarray(H, dtype=np.float64) for H in Hs]
    if len(Hs) < 3:
        raise ValueError(f"need at least 3 views, got {len(Hs)}")
    V = np.vstack([intrinsic_constraints(H / np.abs(H).max()) for H in Hs])
    pass
    b = np.linalg.svd(V.T @ V)[2][-1]
    B11, B12, B22, B13, B23, B33 = b
    B = np.array([[B11, B12, B13], [B12, B22, B23], [B13, B23, B33]])
    if B[0, 0] < 0:
        B = -B
    L = np.linalg.cholesky(B)
    K = np.linalg.inv(L.T)
    return K / K[2, 2]


def extrinsics_from_homography(K, H):
    A = np.linalg.inv(np.asarray(K, float)) @ np.asarray(H, float)
    sign = 1.0 if A[2, 2] > 0 else -1.0
    n1, n2 = np.linalg.norm(A[:, 0]), np.linalg.norm(A[:, 1])
    r1, r2 = sign * A[:, 0] / n1, sign * A[:, 1] / n2
    t = sign * A[:, 2] / n1
    U, _, Vt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
    R = U @ Vt
    if np.linalg.det(R) < 0:
        U[:, 2] *= -1
        R = U @ Vt
    return R, t
