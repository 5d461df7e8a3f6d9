# Corpus of the rule table (dtscal_lib/exercise_rules.py) for tests/test_grading_fairness.py: the self-check and the
# grader agree on every function (self-check passes <=> full marks); the charged functions lose points in both.
# rule: the precision contract: camera_height_pitch in float32 is near enough for a loose value check (the
# self-check's pitch tolerance was 1e-5 deg) but fails the contract, in the self-check and the grader alike
# charged: camera_height_pitch
# expect: computed in float64 (the precision contract)

import numpy as np


def camera_height_pitch(H, K):
    H, K = np.asarray(H, np.float32), np.asarray(K, np.float32)
    M = np.linalg.solve(K, np.linalg.inv(H))
    lam = np.float32(2.0) / (np.linalg.norm(M[:, 0]) + np.linalg.norm(M[:, 1]))
    r1, r2, t = lam * M[:, 0], lam * M[:, 1], lam * M[:, 2]
    if (np.float32(0.25) * r1 + t)[2] < 0:
        r1, r2, t = -r1, -r2, -t
    R = np.column_stack([r1, r2, np.cross(r1, r2)])
    axis = R[2]
    return np.array([-(R.T @ t)[2], np.degrees(np.arctan2(-axis[2], np.hypot(axis[0], axis[1])))], dtype=np.float64)
