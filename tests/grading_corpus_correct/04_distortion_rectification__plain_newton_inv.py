# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: plain_newton_inv
# formulation: plain distortion, Newton with the analytic Jacobian (batched solve), inv(new_K) maps

import numpy as np


def distort_normalized(xy, dist):
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    k1, k2, p1, p2, k3 = np.asarray(dist, dtype=np.float64).ravel()[:5]
    x, y = xy[:, 0], xy[:, 1]
    r2 = x ** 2 + y ** 2
    radial = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    return np.column_stack([x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x ** 2),
                            y * radial + p1 * (r2 + 2 * y ** 2) + 2 * p2 * x * y])


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
    K = np.asarray(K, float)
    w, h = int(size[0]), int(size[1])
    u, v = np.meshgrid(np.arange(w), np.arange(h))
    pix = np.stack([u.ravel(), v.ravel(), np.ones(u.size)]).astype(float)
    rays = np.linalg.inv(np.asarray(new_K, float)) @ pix
    xy = distort_normalized((rays[:2] / rays[2]).T, dist)
    uv = np.column_stack([xy, np.ones(len(xy))]) @ K.T
    return uv[:, 0].reshape(h, w).astype(np.float32), uv[:, 1].reshape(h, w).astype(np.float32)
