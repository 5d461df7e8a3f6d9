# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: complex_analytic_indices
# formulation: complex numbers, analytic Newton, np.indices maps

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


def undistort_normalized(xy_d, dist):
    xy_d = np.asarray(xy_d, dtype=np.float64).reshape(-1, 2)
    k1, k2, p1, p2, k3 = np.asarray(dist, dtype=np.float64).ravel()[:5]
    xy = xy_d.copy()
    for _ in range(100):
        f = distort_normalized(xy, dist) - xy_d
        if np.abs(f).max(initial=0.0) < 1e-14:
            break
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        rho = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
        drho = k1 + 2 * k2 * r2 + 3 * k3 * r2 ** 2
        J = np.empty((len(xy), 2, 2))
        J[:, 0, 0] = rho + 2 * x * x * drho + 2 * p1 * y + 6 * p2 * x
        J[:, 0, 1] = J[:, 1, 0] = 2 * x * y * drho + 2 * p1 * x + 2 * p2 * y
        J[:, 1, 1] = rho + 2 * y * y * drho + 6 * p1 * y + 2 * p2 * x
        xy = xy - np.linalg.solve(J, f[:, :, None])[:, :, 0]
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
