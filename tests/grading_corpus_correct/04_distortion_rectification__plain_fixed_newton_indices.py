# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: plain_fixed_newton_indices
# formulation: plain, fixed point then Newton, np.indices maps

import numpy as np


def distort_normalized(xy, dist):
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    k1, k2, p1, p2, k3 = np.asarray(dist, dtype=np.float64).ravel()[:5]
    x, y = xy[:, 0], xy[:, 1]
    r2 = x ** 2 + y ** 2
    radial = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    return np.column_stack([x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x ** 2),
                            y * radial + p1 * (r2 + 2 * y ** 2) + 2 * p2 * x * y])


def _jac(x, y, k1, k2, p1, p2, k3):
    r2 = x * x + y * y
    rho = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    drho = k1 + 2 * k2 * r2 + 3 * k3 * r2 ** 2
    return (rho + 2 * x * x * drho + 2 * p1 * y + 6 * p2 * x, 2 * x * y * drho + 2 * p1 * x + 2 * p2 * y,
            rho + 2 * y * y * drho + 6 * p1 * y + 2 * p2 * x)


def undistort_normalized(xy_d, dist):
    xy_d = np.asarray(xy_d, dtype=np.float64).reshape(-1, 2)
    c = [float(v) for v in np.ravel(dist)[:5]]
    xy = xy_d.copy()
    for _ in range(5):  # a few fixed-point steps to get close, then Newton
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        rho = 1 + c[0] * r2 + c[1] * r2 ** 2 + c[4] * r2 ** 3
        tx = 2 * c[2] * x * y + c[3] * (r2 + 2 * x * x)
        ty = c[2] * (r2 + 2 * y * y) + 2 * c[3] * x * y
        xy = np.column_stack([(xy_d[:, 0] - tx) / rho, (xy_d[:, 1] - ty) / rho])
        if not np.all(np.isfinite(xy)):
            xy = xy_d.copy()
            break
    for _ in range(80):
        f = distort_normalized(xy, dist) - xy_d
        if np.abs(f).max(initial=0.0) < 1e-14:
            break
        a, b, d = _jac(xy[:, 0], xy[:, 1], *c)
        det = a * d - b * b
        xy = xy - np.column_stack([(d * f[:, 0] - b * f[:, 1]) / det, (a * f[:, 1] - b * f[:, 0]) / det])
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
