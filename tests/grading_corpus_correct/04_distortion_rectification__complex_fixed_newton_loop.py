# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: complex_fixed_newton_loop
# formulation: complex numbers for r^2, fixed point then Newton, maps row by row

import numpy as np


def distort_normalized(xy, dist):
    xy = np.asarray(xy, float)
    k1, k2, p1, p2, k3 = np.asarray(dist, float)[:5]
    z = xy[:, 0] + 1j * xy[:, 1]
    r2 = np.abs(z) ** 2
    radial = np.polyval([k3, k2, k1, 1.0], r2)
    x, y = z.real, z.imag
    tx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    ty = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([x * radial + tx, y * radial + ty], axis=-1)


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
    w, h = int(size[0]), int(size[1])
    K, nKi = np.asarray(K, float), np.linalg.inv(np.asarray(new_K, float))
    map_x = np.empty((h, w), np.float32)
    map_y = np.empty((h, w), np.float32)
    us = np.arange(w, dtype=float)
    for v in range(h):
        rays = np.column_stack([us, np.full(w, float(v)), np.ones(w)]) @ nKi.T
        xy = distort_normalized(rays[:, :2] / rays[:, 2:], dist)
        p = np.column_stack([xy, np.ones(w)]) @ K.T
        map_x[v], map_y[v] = p[:, 0], p[:, 1]
    return map_x, map_y
