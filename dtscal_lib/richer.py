"""Richer models fitted to a calibration's own corners: does a finer lens or a bent board explain the residual?

When the residual of a calibration is several times the corner noise measured without a model
(:func:`dtscal_lib.quality.corner_noise`), something in the data is not what the model assumes. The
verdict must not guess what: it fits the candidates and asks how much of the residual each explains.

* **finer lens models**: k3 (OpenCV's ``plumb_bob`` with 5 coefficients), OpenCV's 8-coefficient
  rational model (``CALIB_RATIONAL_MODEL``: k1, k2, p1, p2, k3, k4, k5, k6), and tangential terms for
  Zhang's ``radial2``;
* **a board that is not flat**: mrcal's two-parameter warp of the calibration object
  (``mrcal.ref_calibration_object``, ``calobject_warp``): the board point at normalised grid
  coordinates ``xr = i / (W - 1)``, ``yr = j / (H - 1)`` is lifted out of the board's plane by
  ``z = warp_x * 4 xr (1 - xr) + warp_y * 4 yr (1 - yr)``, a parabola along each axis whose value at
  the board's middle is the warp (mrcal: "the maximum additive deflection along the x and y axes").
  The sign is mrcal's: ``+z`` along ``x cross y`` of the board's own axes.

Each candidate is a full Levenberg-Marquardt refinement of every parameter (the intrinsics, every
pose, the extra terms) started from the calibration's solution with the extra terms at 0, the normal
equations reduced to the intrinsics through the Schur complement of the poses (as
:mod:`dtscal_lib.calibration` does), projected with ``cv2.projectPoints`` and its Jacobian.

The measure is the **share of the excess** a candidate explains: with ``s`` the residual sigma per
coordinate (``sqrt(|e|^2 / (2N - p))``, each fit with its own ``p``) and ``n`` the model-free corner
noise, ``(s^2 - s_c^2) / (s^2 - n^2)``: 1 when the candidate brings the residual down to the noise, 0
when it changes nothing.

>>> import numpy as np, cv2
>>> from dtscal_lib.calibration import calibrate
>>> obj = np.array([[i * 0.03, j * 0.03] for j in range(6) for i in range(9)])
>>> K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
>>> z = 0.002 * 4 * (obj[:, 0] / 0.24) * (1 - obj[:, 0] / 0.24)  # 2 mm along the board's x
>>> P = np.column_stack([obj, z])
>>> poses = [(0.4, 0.1, 0.0), (-0.4, 0.2, 0.1), (0.1, -0.4, 0.0), (-0.2, -0.3, 0.2), (0.3, 0.35, -0.1)]
>>> img = [cv2.projectPoints(P, np.array(r), np.array([-0.12, -0.08, 0.4]), K, np.zeros(5))[0].reshape(-1, 2)
...        for r in poses]
>>> res = calibrate([obj] * 5, img, (640, 480))
>>> w = fit_richer(res, "warp")
>>> [round(1000 * x, 2) for x in w.warp]
[2.0, 0.0]
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["RicherFit", "fit_richer", "candidates", "excess_share"]

#: OpenCV's 8 distortion coefficients, in its order
DIST8 = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")


@dataclass
class RicherFit:
    """One candidate fitted: its name, the extra terms, the residual it leaves.

    name : ``"k3"``, ``"rational"``, ``"tangential"`` or ``"warp"``
    dist_names : the distortion coefficients estimated (of :data:`DIST8`)
    dist : (8,) the distortion, OpenCV's order
    warp : (2,) mrcal's ``calobject_warp`` in the object points' unit (0, 0 for a lens candidate)
    rms : pixels per point;  sigma : per coordinate, ``sqrt(|e|^2 / (2N - p))``;  n_params : p
    K : (3, 3)
    """

    name: str
    dist_names: tuple
    dist: np.ndarray
    warp: np.ndarray
    rms: float
    sigma: float
    n_params: int
    K: np.ndarray


def candidates(result) -> list[str]:
    """The finer lens models worth fitting for a result's model (the board warp is always one more)."""
    if result.model == "radial2":
        return ["tangential", "rational"]
    return ["rational"] if "k3" in result.std else ["k3", "rational"]


def _dist_names(result, name: str) -> tuple:
    base = ("k1", "k2") if result.model == "radial2" else ("k1", "k2", "p1", "p2")
    if "k3" in result.std:
        base = base + ("k3",)
    extra = {"warp": (), "base": (), "tangential": ("p1", "p2"), "k3": ("k3",),
             "rational": ("p1", "p2", "k3", "k4", "k5", "k6")}[name]
    return tuple(n for n in DIST8 if n in base or n in extra)


def _grid_shape(obj_list):
    """Per view (N_i, 2) normalised grid coordinates ``(xr, yr)`` in [0, 1] of the board's points, from the
    extent of every view's points together (the whole board, as mrcal's ``W - 1`` and ``H - 1``)."""
    allp = np.concatenate(obj_list)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    span = np.where(hi - lo > 0, hi - lo, 1.0)
    return [(o - lo) / span for o in obj_list]


class _Fit:
    def __init__(self, result, name: str):
        self.obj = [np.asarray(o, dtype=np.float64)[:, :2] for o in result.object_points]
        self.img = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in result.image_points]
        self.shape = [4.0 * g * (1.0 - g) for g in _grid_shape(self.obj)]  # (N_i, 2): dx, dy
        self.skew = bool(result.skew)
        self.warp = name == "warp"
        self.dnames = _dist_names(result, name)
        self.didx = [DIST8.index(n) for n in self.dnames]
        d8 = np.zeros(8)
        d8[:5] = np.asarray(result.dist, dtype=np.float64)[:5]
        K = result.K
        self.theta = np.concatenate([[K[0, 0], K[1, 1], K[0, 2], K[1, 2]], [K[0, 1]] if self.skew else [],
                                     d8[self.didx], np.zeros(2) if self.warp else []])
        self.poses = np.column_stack([np.asarray(result.rvecs, float).reshape(-1, 3),
                                      np.asarray(result.tvecs, float).reshape(-1, 3)])

    def unpack(self, theta):
        fx, fy, cx, cy = theta[:4]
        k = 4
        s = 0.0
        if self.skew:
            s, k = theta[4], 5
        d8 = np.zeros(8)
        d8[self.didx] = theta[k:k + len(self.didx)]
        k += len(self.didx)
        w = theta[k:k + 2] if self.warp else np.zeros(2)
        return fx, fy, cx, cy, s, d8, w

    def view(self, theta, pose, v, jacobian=True):
        fx, fy, cx, cy, s, d8, w = self.unpack(theta)
        P = np.column_stack([self.obj[v], self.shape[v] @ w])
        K0 = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        q, J = cv2.projectPoints(P.reshape(-1, 1, 3), pose[:3], pose[3:], K0, d8)
        q = q.reshape(-1, 2).copy()
        ydn = (q[:, 1] - cy) / fy
        q[:, 0] += s * ydn
        r = (q - self.img[v]).ravel()
        if not jacobian:
            return r, None, None
        J = J.reshape(-1, 2, J.shape[1])
        cols = [J[:, :, 6], J[:, :, 7], J[:, :, 8], J[:, :, 9]]
        if self.skew:
            cols.append(np.column_stack([ydn, np.zeros_like(ydn)]))
        cols += [J[:, :, 10 + i] for i in self.didx]
        Je = J[:, :, :6].copy()
        if self.warp:
            R = cv2.Rodrigues(pose[:3])[0]
            dz = J[:, :, 3:6] @ R[:, 2]  # d pixel / d (board z)
            cols += [dz * self.shape[v][:, 0:1], dz * self.shape[v][:, 1:2]]
        Ji = np.stack(cols, axis=2)  # (N, 2, n)
        if self.skew:  # q_x += s * (q_y - cy) / fy: every term but fx, fy, cx, cy, s moves q_y
            k0 = 5
            Ji[:, 0, k0:] += (s / fy) * Ji[:, 1, k0:]
            Je[:, 0, :] += (s / fy) * Je[:, 1, :]
        return r, Ji.reshape(-1, Ji.shape[2]), Je.reshape(-1, 6)

    def cost(self, theta, poses) -> float:
        return float(sum((self.view(theta, poses[v], v, jacobian=False)[0] ** 2).sum() for v in range(len(self.obj))))

    def solve(self, max_iter: int = 30):
        theta, poses = self.theta.copy(), self.poses.copy()
        lam = 1e-3
        cost = self.cost(theta, poses)
        for _ in range(max_iter):
            n = len(theta)
            A = np.zeros((n, n))
            gi = np.zeros(n)
            Bs, Cs, gv = [], [], []
            for v in range(len(self.obj)):
                r, Ji, Je = self.view(theta, poses[v], v)
                A += Ji.T @ Ji
                gi += Ji.T @ r
                Bs.append(Ji.T @ Je)
                Cs.append(Je.T @ Je)
                gv.append(Je.T @ r)
            improved = False
            for _ in range(10):
                Ad = A + lam * np.diag(np.diag(A))
                Cd = [C + lam * np.diag(np.diag(C)) for C in Cs]
                Ci = [np.linalg.inv(C) for C in Cd]
                S = Ad - sum(B @ c @ B.T for B, c in zip(Bs, Ci))
                rhs = -gi + sum(B @ c @ g for B, c, g in zip(Bs, Ci, gv))
                try:
                    di = np.linalg.solve(S, rhs)
                except np.linalg.LinAlgError:
                    lam *= 10
                    continue
                dp = np.array([-c @ (g + B.T @ di) for B, c, g in zip(Bs, Ci, gv)])
                t2, p2 = theta + di, poses + dp
                c2 = self.cost(t2, p2)
                if np.isfinite(c2) and c2 < cost:
                    done = cost - c2 < 1e-10 * cost
                    theta, poses, cost, improved = t2, p2, c2, True
                    lam = max(lam / 10, 1e-9)
                    break
                lam *= 10
            if not improved or done:
                break
        self.theta, self.poses = theta, poses
        return cost


def fit_richer(result, name: str) -> RicherFit:
    """Fit candidate ``name`` (``"k3"``, ``"rational"``, ``"tangential"``, ``"warp"`` or ``"base"``: the
    result's own model, refitted by this solver) to a result's own views, starting from its solution."""
    f = _Fit(result, name)
    cost = f.solve()
    n_pts = sum(len(p) for p in f.img)
    p = len(f.theta) + 6 * len(f.obj)
    fx, fy, cx, cy, s, d8, w = f.unpack(f.theta)
    return RicherFit(name, f.dnames, d8, np.asarray(w, dtype=np.float64), float(np.sqrt(cost / n_pts)),
                     float(np.sqrt(cost / max(2 * n_pts - p, 1))), p,
                     np.array([[fx, s, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]))


def excess_share(sigma: float, sigma_candidate: float, noise: float) -> float:
    """How much of the residual above the noise a candidate explains: ``(s^2 - s_c^2) / (s^2 - n^2)``
    (0 when the residual is at the noise already)."""
    excess = sigma ** 2 - noise ** 2
    if excess <= 0:
        return 0.0
    return float(np.clip((sigma ** 2 - sigma_candidate ** 2) / excess, 0.0, 1.0))
