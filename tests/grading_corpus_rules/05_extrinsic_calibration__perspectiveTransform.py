# Corpus of the rule table (dtscal_lib/exercise_rules.py) for tests/test_exercise_rules.py: the self-check and the
# grader agree on every function (self-check passes <=> full marks); the charged functions lose points in both.
# rule: cv2.perspectiveTransform computes pixel_to_ground
# charged: pixel_to_ground
# expect: calls cv2.perspectiveTransform, which does the exercise for you

import cv2
import numpy as np


def board_ground_points(cols, rows, square, x0, y0):
    j, i = np.indices((int(rows), int(cols)), dtype=np.float64)
    return np.column_stack([(x0 + square * j).ravel(), (y0 + square * i).ravel()])
def pixel_to_ground(H, uv):
    return cv2.perspectiveTransform(np.asarray(uv, float).reshape(-1, 1, 2), np.asarray(H, float)).reshape(-1, 2)


def camera_height_pitch(H, K):
    M = np.linalg.solve(K, np.linalg.inv(H))
    lam = 2.0 / (np.linalg.norm(M[:, 0]) + np.linalg.norm(M[:, 1]))
    r1, r2, t = lam * M[:, 0], lam * M[:, 1], lam * M[:, 2]
    if (0.25 * r1 + t)[2] < 0:
        r1, r2, t = -r1, -r2, -t
    R = np.column_stack([r1, r2, np.cross(r1, r2)])
    axis = R[2]  # the optical axis in the robot frame
    return np.array([float(-(R.T @ t)[2]), float(np.degrees(np.arctan2(-axis[2], np.hypot(axis[0], axis[1]))))])
