# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: horner_numeric_indices
# formulation: Horner's rule, Newton with a numerical Jacobian, maps from np.indices

import numpy as np


def distort_normalized(xy, dist):
    xy = np.array(xy, dtype=float)
    k1, k2, p1, p2, k3 = [float(c) for c in np.ravel(dist)[:5]]
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    out = np.empty_like(xy)
    out[:, 0] = x * radial + dx
    out[:, 1] = y * radial + dy
    return out


def undistort_normalized(xy_d, dist):
    xy_d = np.asarray(xy_d, float).reshape(-1, 2)
    xy = xy_d.copy()
    h = 1e-7
    for _ in range(60):
        f = distort_normalized(xy, dist) - xy_d
        if np.max(np.abs(f), initial=0.0) < 1e-14:
            break
        fx = (distort_normalized(xy + [h, 0], dist) - distort_normalized(xy - [h, 0], dist)) / (2 * h)
        fy = (distort_normalized(xy + [0, h], dist) - distort_normalized(xy - [0, h], dist)) / (2 * h)
        det = fx[:, 0] * fy[:, 1] - fy[:, 0] * fx[:, 1]
        xy = xy - np.column_stack([(fy[:, 1] * f[:, 0] - fy[:, 0] * f[:, 1]) / det,
                                   (fx[:, 0] * f[:, 1] - fx[:, 1] * f[:, 0]) / det])
    return xy


def rectification_maps(K, dist, new_K, size):
    w, h = map(int, size)
    nK = np.asarray(new_K, dtype=np.float64)
    v, u = np.indices((h, w), dtype=np.float64)
    y = (v - nK[1, 2]) / nK[1, 1]
    x = (u - nK[0, 2] - nK[0, 1] * y) / nK[0, 0]
    xy_d = distort_normalized(np.column_stack([x.ravel(), y.ravel()]), dist)
    K = np.asarray(K, dtype=np.float64)
    map_x = (K[0, 0] * xy_d[:, 0] + K[0, 1] * xy_d[:, 1] + K[0, 2]).reshape(h, w)
    map_y = (K[1, 1] * xy_d[:, 1] + K[1, 2]).reshape(h, w)
    return np.float32(map_x), np.float32(map_y)
