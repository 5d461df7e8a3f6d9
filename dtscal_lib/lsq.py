"""The least-squares problem of calibration: residuals, block Jacobians, Levenberg-Marquardt, covariance.

Step 5 of :func:`dtscal_lib.calibration.calibrate`: the reprojection error over every parameter
(``fx, fy, cx, cy, (s), distortion`` and 6 pose parameters per view), its Jacobian in blocks, and
Levenberg-Marquardt solved through the Schur complement of the block-diagonal pose part (``O(V)`` a step);
then the normal equations at the solution (:class:`~dtscal_lib.covariance.NormalBlocks`) that the
standard deviations and the projection uncertainty propagate.
"""

from __future__ import annotations

import cv2
import numpy as np

from .camera import project_points
from .covariance import NormalBlocks, honest_intrinsic_covariance
from .covariance import rodrigues as _rodrigues

__all__ = ["MAX_ITERATIONS", "dist_indices", "normal_blocks"]

_DIST_NAMES = ("k1", "k2", "p1", "p2", "k3")
#: Levenberg-Marquardt stops after this many accepted steps; a calibration that needs them all has not
#: converged (:func:`dtscal_lib.calibration.calibrate` says so). The kit's solves take 4-30
#: (tests/test_calibration.py asserts convergence on real and synthetic views)
MAX_ITERATIONS = 200


def _dist_indices(model: str, fix_k3: bool) -> list[int]:
    if model == "radial2":
        return [0, 1]
    return [0, 1, 2, 3] if fix_k3 else [0, 1, 2, 3, 4]


def _param_names(skew: bool, dist_idx: list[int]) -> list[str]:
    return ["fx", "fy", "cx", "cy"] + (["skew"] if skew else []) + [_DIST_NAMES[i] for i in dist_idx]


def _unpack(theta: np.ndarray, skew: bool, dist_idx: list[int]) -> tuple[np.ndarray, np.ndarray]:
    fx, fy, cx, cy = theta[:4]
    s = theta[4] if skew else 0.0
    dist = np.zeros(5)
    dist[dist_idx] = theta[4 + int(skew):]
    K = np.eye(3)
    K[0] = (fx, s, cx)
    K[1, 1:] = (fy, cy)
    return K, dist


class _Problem:
    """Residuals and block Jacobians of the reprojection error.

    Intrinsic vector ``theta = [fx, fy, cx, cy, (s), dist...]``; poses ``(V, 6)``
    rows ``[rvec, t]``. Residual order: per view, per point, ``(du, dv)``.

    The refinement works on all views at once (:meth:`residuals_stacked`,
    :meth:`linearize_stacked`): the projection and its Jacobian are written out in numpy over
    every point of every view (one ``cv2.Rodrigues`` per view for the rotation's derivative),
    instead of one ``cv2.projectPoints`` call per view and step (~40x fewer Python-level calls
    for 40 views). :meth:`residuals` (through :func:`~dtscal_lib.camera.project_points`) is the
    independent reference the tests check it against; :meth:`linearize` gives the same numbers
    split per view.
    """

    def __init__(self, obj, img, skew, dist_idx):
        self.obj3 = [np.column_stack([o, np.zeros(len(o))]) for o in obj]
        self.img = img
        self.skew, self.dist_idx = skew, list(dist_idx)
        self.n_intr = 4 + int(skew) + len(dist_idx)
        counts = np.array([len(o) for o in obj])
        self.counts = counts
        self.starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.intp)
        self.view = np.repeat(np.arange(len(obj)), counts)
        xy = np.concatenate([np.asarray(o, dtype=np.float64)[:, :2] for o in obj])
        self.x, self.y = xy[:, 0].copy(), xy[:, 1].copy()
        self.observed = np.concatenate([np.asarray(m, dtype=np.float64).reshape(-1, 2) for m in img])
        #: a full refinement (:data:`MAX_ITERATIONS`) stopped at its cap instead of converging
        self.capped = False

    def residuals(self, theta, poses) -> list[np.ndarray]:
        """Per view (N_i, 2) ``projected - observed`` pixels (skew honoured), view by view."""
        K, dist = _unpack(theta, self.skew, self.dist_idx)
        return [project_points(o, p[:3], p[3:], K, dist) - m for o, p, m in zip(self.obj3, poses, self.img)]

    def _camera_points(self, poses, jacobian: bool):
        """Board points in the camera frame, (P, 3), and (with ``jacobian``) d Xc / d rvec, (P, 3, 3)."""
        poses = np.asarray(poses, dtype=np.float64)
        R, dR = _rodrigues(poses[:, :3], jacobian)
        R = R[self.view]  # (P, 3, 3)
        t = poses[:, 3:][self.view]
        Xc = R[:, :, 0] * self.x[:, None] + R[:, :, 1] * self.y[:, None] + t
        if not jacobian:
            return Xc, None
        dR = dR[self.view]  # (P, k, i, j) = dR_ij / d r_k
        dXc_dr = (dR[:, :, :, 0] * self.x[:, None, None] + dR[:, :, :, 1] * self.y[:, None, None]).transpose(0, 2, 1)
        return Xc, dXc_dr

    def residuals_stacked(self, theta, poses) -> np.ndarray:
        """``projected - observed`` pixels of all views, (P, 2) (skew honoured)."""
        return self._project(theta, poses, jacobian=False)[0]

    def linearize_stacked(self, theta, poses):
        """Residuals (P, 2), d residual / d intrinsics (P, 2, n_intr), d residual / d pose (P, 2, 6)."""
        return self._project(theta, poses, jacobian=True)

    def _project(self, theta, poses, jacobian: bool):
        K, dist = _unpack(theta, self.skew, self.dist_idx)
        fx, fy, cx, cy, s = K[0, 0], K[1, 1], K[0, 2], K[1, 2], K[0, 1]
        k1, k2, p1, p2, k3 = dist
        Xc, dXc_dr = self._camera_points(poses, jacobian)
        iz = 1.0 / Xc[:, 2]
        xp, yp = Xc[:, 0] * iz, Xc[:, 1] * iz
        xx, yy, xy = xp * xp, yp * yp, xp * yp
        r2 = xx + yy
        rad = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = xp * rad + 2.0 * p1 * xy + p2 * (r2 + 2.0 * xx)
        yd = yp * rad + p1 * (r2 + 2.0 * yy) + 2.0 * p2 * xy
        r = np.empty((len(xp), 2))
        r[:, 0] = fx * xd + s * yd + cx - self.observed[:, 0]
        r[:, 1] = fy * yd + cy - self.observed[:, 1]
        if not jacobian:
            return r, None, None
        # distortion: d(xd, yd) / d(xp, yp)
        drad = 2.0 * (k1 + r2 * (2.0 * k2 + 3.0 * r2 * k3))  # d rad / d r2, times 2
        dxd_dxp = rad + xx * drad + 2.0 * p1 * yp + 6.0 * p2 * xp
        dxd_dyp = xy * drad + 2.0 * p1 * xp + 2.0 * p2 * yp
        dyd_dxp = dxd_dyp
        dyd_dyp = rad + yy * drad + 6.0 * p1 * yp + 2.0 * p2 * xp
        # pixels: u = fx xd + s yd + cx, v = fy yd + cy; d(u, v) / d(xp, yp)
        du_dxp, du_dyp = fx * dxd_dxp + s * dyd_dxp, fx * dxd_dyp + s * dyd_dyp
        dv_dxp, dv_dyp = fy * dyd_dxp, fy * dyd_dyp
        # d(xp, yp) / d Xc = [[iz, 0, -xp iz], [0, iz, -yp iz]]
        dq = np.empty((len(xp), 2, 3))
        dq[:, 0, 0], dq[:, 0, 1] = du_dxp * iz, du_dyp * iz
        dq[:, 0, 2] = -(du_dxp * xp + du_dyp * yp) * iz
        dq[:, 1, 0], dq[:, 1, 1] = dv_dxp * iz, dv_dyp * iz
        dq[:, 1, 2] = -(dv_dxp * xp + dv_dyp * yp) * iz
        Je = np.empty((len(xp), 2, 6))
        Je[:, :, :3] = dq @ dXc_dr
        Je[:, :, 3:] = dq  # d Xc / d t = I
        Ji = np.zeros((len(xp), 2, self.n_intr))
        Ji[:, 0, 0] = xd
        Ji[:, 1, 1] = yd
        Ji[:, 0, 2] = 1.0
        Ji[:, 1, 3] = 1.0
        col = 4
        if self.skew:
            Ji[:, 0, 4] = yd
            col = 5
        terms = {0: (xp * r2, yp * r2), 1: (xp * r2 * r2, yp * r2 * r2), 2: (2.0 * xy, r2 + 2.0 * yy),
                 3: (r2 + 2.0 * xx, 2.0 * xy), 4: (xp * r2 ** 3, yp * r2 ** 3)}
        for c, i in enumerate(self.dist_idx, start=col):
            dxd, dyd = terms[i]
            Ji[:, 0, c] = fx * dxd + s * dyd
            Ji[:, 1, c] = fy * dyd
        return r, Ji, Je

    def linearize(self, theta, poses):
        """Residual vectors and Jacobian blocks per view.

        Returns lists of ``r`` (2N_i,), ``Ji`` (2N_i, n_intr), ``Je`` (2N_i, 6).
        """
        r, Ji, Je = self.linearize_stacked(theta, poses)
        cuts = self.starts[1:]
        return ([a.ravel() for a in np.split(r, cuts)], [a.reshape(-1, self.n_intr) for a in np.split(Ji, cuts)],
                [a.reshape(-1, 6) for a in np.split(Je, cuts)])

    def normal_blocks(self, r, Ji, Je):
        """:func:`_normal_blocks` of the stacked arrays of :meth:`linearize_stacked`."""
        n = self.n_intr
        Ji2, r2 = Ji.reshape(-1, n), r.ravel()
        A = Ji2.T @ Ji2
        gi = Ji2.T @ r2
        if np.all(self.counts == self.counts[0]):  # the usual case (every view sees the whole board)
            V = len(self.counts)
            Jiv, Jev, rv = Ji.reshape(V, -1, n), Je.reshape(V, -1, 6), r.reshape(V, -1, 1)
            JevT = Jev.transpose(0, 2, 1)
            return A, Jiv.transpose(0, 2, 1) @ Jev, JevT @ Jev, gi, (JevT @ rv)[:, :, 0]
        Bs = np.add.reduceat(np.einsum("pai,paj->pij", Ji, Je), self.starts, axis=0)
        Cs = np.add.reduceat(np.einsum("pai,paj->pij", Je, Je), self.starts, axis=0)
        gv = np.add.reduceat(np.einsum("pai,pa->pi", Je, r), self.starts, axis=0)
        return A, Bs, Cs, gi, gv

    def blocks(self, theta, poses) -> NormalBlocks:
        """The normal equations at ``(theta, poses)`` block by block, with each view's share (``O(V)`` memory)."""
        r, Ji, Je = self.linearize_stacked(theta, poses)
        A, Bs, Cs, _, _ = self.normal_blocks(r, Ji, Je)
        n = self.n_intr
        if np.all(self.counts == self.counts[0]):  # every view sees the whole board: batched products
            Jiv = Ji.reshape(len(self.counts), -1, n)
            JivT = Jiv.transpose(0, 2, 1)
            A_views, g = JivT @ Jiv, (JivT @ r.reshape(len(self.counts), -1, 1))[:, :, 0]
        else:
            A_views = np.add.reduceat(np.einsum("pai,paj->pij", Ji, Ji), self.starts, axis=0)
            g = np.add.reduceat(np.einsum("pai,pa->pi", Ji, r), self.starts, axis=0)
        dof = r.size - (self.n_intr + 6 * len(self.counts))  # > 0: checked on entry to calibrate()
        return NormalBlocks(A, Bs, Cs, A_views, g, _cost(r) / dof, _param_names(self.skew, self.dist_idx))


def _normal_blocks(rs, Jis, Jes):
    """``A = sum Ji^T Ji``, ``B_v = Ji^T Je``, ``C_v = Je^T Je``, gradients ``g_i``, ``g_v``."""
    A = sum(Ji.T @ Ji for Ji in Jis)
    Bs = np.stack([Ji.T @ Je for Ji, Je in zip(Jis, Jes)])
    Cs = np.stack([Je.T @ Je for Je in Jes])
    gi = sum(Ji.T @ r for Ji, r in zip(Jis, rs))
    gv = np.stack([Je.T @ r for Je, r in zip(Jes, rs)])
    return A, Bs, Cs, gi, gv


def _schur_solve(A, Bs, Cs, gi, gv, lam):
    """Solve the Marquardt-damped normal equations ``(J^T J + lam diag) d = -J^T r`` via Schur."""
    Ad = A + lam * np.diag(np.maximum(np.diag(A), 1e-12))
    cd = np.maximum(np.einsum("vii->vi", Cs), 1e-12)
    Cd = Cs + lam * np.einsum("vi,ij->vij", cd, np.eye(6))
    Cinv = np.linalg.inv(Cd)
    BCi = np.einsum("vij,vjk->vik", Bs, Cinv)  # (V, n, 6)
    S = Ad - np.einsum("vij,vkj->ik", BCi, Bs)
    rhs = -gi + np.einsum("vij,vj->i", BCi, gv)
    di = np.linalg.solve(S, rhs)
    dv = -np.einsum("vij,vj->vi", Cinv, gv + np.einsum("vji,j->vi", Bs, di))
    return di, dv


def _cost(r: np.ndarray) -> float:
    return float(np.einsum("ij,ij->", r, r))


def _refine(problem: _Problem, theta, poses, max_iter: int = MAX_ITERATIONS):
    """Levenberg-Marquardt with Marquardt's diagonal scaling; returns ``theta, poses, iterations``.

    A trial step costs only the residuals; the Jacobian is computed once a step is accepted.
    """
    r, Ji, Je = problem.linearize_stacked(theta, poses)
    cost = _cost(r)
    lam = 1e-3
    it = 0
    for it in range(1, max_iter + 1):
        A, Bs, Cs, gi, gv = problem.normal_blocks(r, Ji, Je)
        improved = False
        while lam < 1e16:
            try:
                di, dv = _schur_solve(A, Bs, Cs, gi, gv, lam)
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            t_new, p_new = theta + di, poses + dv
            if t_new[0] <= 0 or t_new[1] <= 0:
                lam *= 10.0
                continue
            try:
                with np.errstate(all="ignore"):
                    cost_new = _cost(problem.residuals_stacked(t_new, p_new))
            except cv2.error:
                lam *= 10.0
                continue
            if np.isfinite(cost_new) and cost_new <= cost:
                improved = True
                break
            lam *= 10.0
        if not improved:
            break
        small_step = np.all(np.abs(di) <= 1e-12 * (np.abs(theta) + 1e-6)) and np.all(
            np.abs(dv) <= 1e-12 * (np.abs(poses) + 1e-6)
        )
        stalled = cost - cost_new <= 1e-16 * cost
        theta, poses, cost = t_new, p_new, cost_new
        lam = max(lam / 10.0, 1e-12)
        if small_step or stalled or cost == 0.0:
            break
        r, Ji, Je = problem.linearize_stacked(theta, poses)
    else:
        if max_iter >= MAX_ITERATIONS and it:  # the cap ended the full refinement, not a stop criterion
            problem.capped = True
    return theta, poses, it


def _intrinsic_covariance(problem: _Problem, theta, poses):
    """``sigma^2``, the intrinsics' honest covariance, the noise model's ``sigma^2 S^-1`` and the method in words.

    See :mod:`dtscal_lib.covariance`: the larger of the noise model and a CR2 sandwich over the views.
    """
    blocks = problem.blocks(theta, poses)
    cov, noise, method = honest_intrinsic_covariance(blocks)
    return blocks.sigma2, cov, noise, method



def dist_indices(model: str, std) -> list[int]:
    """Indices into ``[k1, k2, p1, p2, k3]`` of the distortion terms a kit result estimated (its ``std``'s keys)."""
    return _dist_indices(model, fix_k3="k3" not in std)


def normal_blocks(result) -> NormalBlocks:
    """The normal equations at a result's solution, block by block, from its views and parameters."""
    idx = dist_indices(result.model, result.std)
    problem = _Problem([np.asarray(o, dtype=np.float64)[:, :2] for o in result.object_points],
                       [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in result.image_points],
                       result.skew, idx)
    K = result.K
    theta = np.concatenate([[K[0, 0], K[1, 1], K[0, 2], K[1, 2]], [K[0, 1]] if result.skew else [],
                            np.asarray(result.dist)[idx]])
    return problem.blocks(theta, np.column_stack([result.rvecs, result.tvecs]))
