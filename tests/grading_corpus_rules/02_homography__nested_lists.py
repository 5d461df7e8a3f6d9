# Corpus of the rule table (dtscal_lib/exercise_rules.py) for tests/test_grading_fairness.py: the self-check and the
# grader agree on every function (self-check passes <=> full marks); the charged functions lose points in both.
# rule: a nested list is converted for the values and refused by the return-type rule, the same way for every
# function
# charged: apply_homography, estimate_homography
# expect: got a list: return numpy arrays

import math

import numpy as np


def _apply(H, pts):
    p = np.asarray(pts, float).reshape(-1, 2)
    q = np.column_stack([p, np.ones(len(p))]) @ np.asarray(H, float).T
    return q[:, :2] / q[:, 2:]


def apply_homography(H, pts):
    return _apply(H, pts).tolist()


def _normalizer(p):
    c = p.mean(axis=0)
    s = math.sqrt(2) / np.mean(np.linalg.norm(p - c, axis=1))
    return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1.0]])


def estimate_homography(src, dst):
    src = np.asarray(src, float).reshape(-1, 2)
    dst = np.asarray(dst, float).reshape(-1, 2)
    Ts, Td = _normalizer(src), _normalizer(dst)
    s, d = _apply(Ts, src), _apply(Td, dst)
    A = []
    for (x, y), (u, v) in zip(s, d):
        A.append([x, y, 1, 0, 0, 0, -u * x, -u * y, -u])
        A.append([0, 0, 0, x, y, 1, -v * x, -v * y, -v])
    h = np.linalg.svd(np.array(A))[2][-1]
    H = np.linalg.inv(Td) @ h.reshape(3, 3) @ Ts
    return (H / H[2, 2]).tolist()
