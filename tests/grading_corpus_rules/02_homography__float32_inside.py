# Corpus of the rule table (dtscal_lib/exercise_rules.py) for tests/test_grading_fairness.py: the self-check and the
# grader agree on every function (self-check passes <=> full marks); the charged functions lose points in both.
# rule: the precision contract: float32 arithmetic inside fails in the self-check and the grader alike
# charged: estimate_homography
# expect: float32 arithmetic

import math

import numpy as np


def _normalizer(p):
    c = p.mean(axis=0)
    s = math.sqrt(2) / np.mean(np.linalg.norm(p - c, axis=1))
    return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1.0]], dtype=np.float32)


def estimate_homography(src, dst):
    src = np.asarray(src, np.float32).reshape(-1, 2)
    dst = np.asarray(dst, np.float32).reshape(-1, 2)
    Ts, Td = _normalizer(src), _normalizer(dst)
    s = src @ Ts[:2, :2].T + Ts[:2, 2]
    d = dst @ Td[:2, :2].T + Td[:2, 2]
    A = []
    for (x, y), (u, v) in zip(s, d):
        A.append([x, y, 1, 0, 0, 0, -u * x, -u * y, -u])
        A.append([0, 0, 0, x, y, 1, -v * x, -v * y, -v])
    h = np.linalg.svd(np.array(A, dtype=np.float32))[2][-1]
    H = np.linalg.inv(Td) @ h.reshape(3, 3) @ Ts
    return (H / H[2, 2]).astype(np.float64)
