# Corpus of the rule table (dtscal_lib/exercise_rules.py) for tests/test_exercise_rules.py: the self-check and the
# grader agree on every function (self-check passes <=> full marks); the charged functions lose points in both.
# rule: SciPy is not allowed in any notebook (numpy.linalg has everything): the polar decomposition and the
# spectral norm by scipy.linalg are refused with the grader's words
# charged: extrinsics_from_homography
# expect: not allowed: extrinsics_from_homography uses scipy.linalg.polar

import math

import numpy as np
import scipy.linalg


def intrinsic_constraints(H):
    H = np.asarray(H, dtype=np.float64)
    rows = []
    for a, b in ((0, 1), (0, 0), (1, 1)):
        rows.append([])
        for i, j in ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2)):
            E = np.zeros((3, 3))
            E[i, j] = E[j, i] = 1.0
            rows[-1].append(H[:, a] @ E @ H[:, b])
    r = np.array(rows)
    return np.vstack([r[0], r[1] - r[2]])


def intrinsics_from_homographies(Hs):
    Hs = [np.asarray(H, dtype=np.float64) for H in Hs]
    if len(Hs) < 3:
        raise ValueError(f"need at least 3 views, got {len(Hs)}")
    V = np.vstack([intrinsic_constraints(H / np.linalg.norm(H)) for H in Hs])
    pass
    b = np.linalg.svd(V, full_matrices=False)[2][-1]
    B11, B12, B22, B13, B23, B33 = b
    cy = (B12 * B13 - B11 * B23) / (B11 * B22 - B12 ** 2)
    lam = B33 - (B13 ** 2 + cy * (B12 * B13 - B11 * B23)) / B11
    fx = math.sqrt(lam / B11)
    fy = math.sqrt(lam * B11 / (B11 * B22 - B12 ** 2))
    s = -B12 * fx ** 2 * fy / lam
    cx = s * cy / fy - B13 * fx ** 2 / lam
    return np.array([[fx, s, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
def extrinsics_from_homography(K, H):
    A = np.linalg.inv(np.asarray(K, float)) @ np.asarray(H, float)
    lam = 1.0 / np.linalg.norm(A[:, 0])
    if A[2, 2] < 0:
        lam = -lam
    r1, r2, t = lam * A[:, 0], lam * A[:, 1], lam * A[:, 2]
    R = scipy.linalg.polar(np.column_stack([r1, r2, np.cross(r1, r2)]))[0]
    return R, t
