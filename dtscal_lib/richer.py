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
>>> [float(round(1000 * x, 2)) + 0.0 for x in w.warp]
[2.0, 0.0]
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .covariance import rodrigues

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
        self.view_of = np.repeat(np.arange(len(self.obj)), [len(o) for o in self.obj])
        self.xy, self.uv = np.concatenate(self.obj), np.concatenate(self.img)
        self.shape_all = np.concatenate(self.shape)
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

    def project(self, theta, poses, jacobian=True):
        """Residuals (2N,) of every view at once; with the Jacobian, its intrinsic part (2N, n) and pose part
        (2N, 6) (one ``cv2.projectPoints`` call for all points, in the camera frame)."""
        fx, fy, cx, cy, s, d8, w = self.unpack(theta)
        R, dR = rodrigues(poses[:, :3], jacobian=jacobian)
        Rv = R[self.view_of]
        Pb = np.column_stack([self.xy, self.shape_all @ w])
        Pc = np.einsum("nij,nj->ni", Rv, Pb) + poses[self.view_of, 3:]
        K0 = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        q, J = cv2.projectPoints(Pc.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K0, d8)
        q = q.reshape(-1, 2).copy()
        ydn = (q[:, 1] - cy) / fy
        q[:, 0] += s * ydn
        r = (q - self.uv).ravel()
        if not jacobian:
            return r, None, None
        J = J.reshape(-1, 2, J.shape[1])
        dP = J[:, :, 3:6]  # d pixel / d camera-frame point (= d / d t at t = 0)
        cols = [J[:, :, 6], J[:, :, 7], J[:, :, 8], J[:, :, 9]]
        if self.skew:
            cols.append(np.column_stack([ydn, np.zeros_like(ydn)]))
        cols += [J[:, :, 10 + i] for i in self.didx]
        if self.warp:
            dz = np.einsum("nci,ni->nc", dP, Rv[:, :, 2])  # d pixel / d (board z)
            cols += [dz * self.shape_all[:, 0:1], dz * self.shape_all[:, 1:2]]
        Ji = np.stack(cols, axis=2)  # (N, 2, n)
        dRv = dR[self.view_of]  # (N, 3 k, 3, 3)
        Je = np.concatenate([np.einsum("nci,nkij,nj->nck", dP, dRv, Pb), dP], axis=2)  # (N, 2, 6)
        if self.skew:  # q_x += s * (q_y - cy) / fy: every term but fx, fy, cx, cy, s moves q_y
            Ji[:, 0, 5:] += (s / fy) * Ji[:, 1, 5:]
            Je[:, 0, :] += (s / fy) * Je[:, 1, :]
        return r, Ji.reshape(-1, Ji.shape[2]), Je.reshape(-1, 6)

    def cost(self, theta, poses) -> float:
        return float((self.project(theta, poses, jacobian=False)[0] ** 2).sum())

    def solve(self, max_iter: int = 12):
        theta, poses = self.theta.copy(), self.poses.copy()
        lam = 1e-3
        cost = self.cost(theta, poses)
        rows = np.repeat(self.view_of, 2)
        starts = np.searchsorted(rows, np.arange(len(self.obj)))
        for _ in range(max_iter):
            r, Ji, Je = self.project(theta, poses)
            A, gi = Ji.T @ Ji, Ji.T @ r
            Bs = np.add.reduceat(Ji[:, :, None] * Je[:, None, :], starts, axis=0)  # (V, n, 6)
            Cs = np.add.reduceat(Je[:, :, None] * Je[:, None, :], starts, axis=0)  # (V, 6, 6)
            gv = np.add.reduceat(Je * r[:, None], starts, axis=0)  # (V, 6)
            improved = done = False
            for _ in range(8):
                Cd = Cs + lam * np.einsum("vii->vi", Cs)[:, :, None] * np.eye(6)
                Ci = np.linalg.inv(Cd)
                BC = Bs @ Ci  # (V, n, 6)
                S = A + lam * np.diag(np.diag(A)) - np.einsum("vij,vkj->ik", BC, Bs)
                rhs = -gi + np.einsum("vij,vj->i", BC, gv)
                try:
                    di = np.linalg.solve(S, rhs)
                except np.linalg.LinAlgError:
                    lam *= 10
                    continue
                dp = -np.einsum("vij,vj->vi", Ci, gv + np.einsum("vij,i->vj", Bs, di))
                t2, p2 = theta + di, poses + dp
                c2 = self.cost(t2, p2)
                if np.isfinite(c2) and c2 < cost:
                    done = cost - c2 < 1e-7 * cost
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
