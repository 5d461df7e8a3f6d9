"""The uncertainty of a calibration: honest standard deviations and their propagation, linear in the views.

A calibration estimates ``n`` intrinsics and 6 pose parameters per view. Its Gauss-Newton normal
matrix ``J^T J`` has a block structure: the intrinsic block ``A`` (n, n), one coupling block
``B_v = Ji_v^T Je_v`` (n, 6) and one pose block ``C_v = Je_v^T Je_v`` (6, 6) per view, and nothing
between two views' poses. :class:`NormalBlocks` keeps exactly that, ``O(V)`` numbers, never the
dense ``(n + 6V)^2`` matrix (1000 views would take 1.1 GB, 4000 views 18 GB).

**What sigma means.** The standard deviation of a parameter says how far it would move if the
calibration were repeated with new views of the same kind: 68 % of repetitions within 1 sigma.
Three estimates of it, measured against each other (``benchmarks/bench_sigma.py``):

* the **noise model** (Hartley-Zisserman, OpenCV's ``stdDeviationsIntrinsics``, mrcal): every
  corner coordinate has independent noise of the residual's sigma, so the covariance is
  ``sigma^2 (J^T J)^-1``, whose intrinsic block is ``sigma^2 S^-1`` with the Schur complement
  ``S = A - sum_v B_v C_v^-1 B_v^T``. Right when the residuals are that noise;
* the **jackknife over views**: leave each view out, re-estimate, and measure how much the
  intrinsics move: ``(V - 1) / V sum_v (d_v - mean d)(d_v - mean d)^T``. Without view ``v`` the
  intrinsics move by ``d_v = (S - S_v)^-1 g_v`` (one Gauss-Newton step from the solution; ``S_v``
  is view ``v``'s share of ``S``, ``g_v = Ji_v^T r_v`` its share of the gradient, its pose gradient
  being 0 at the solution): on OpenCV's real photographs that step agrees with 13 real
  re-calibrations to 0.5 %. It assumes only that the views are independent, but it overstates the
  spread when each view weighs much (every view's removal is a large change): on synthetic views
  with exactly Gaussian noise it is 2.4x the true spread of fx for 6 views, 1.2x for 13;
* the **sandwich over views** with Bell and McCaffrey's leverage correction (CR2):
  ``S^-1 (sum_v u_v u_v^T) S^-1`` with ``u_v = S^1/2 (S - S_v)^-1/2 g_v`` (half way, in the
  exponent, between the plain sandwich and the jackknife above, which is the same with ``-1``). It
  assumes only independent views and is close to unbiased when the noise model is right (table).

On OpenCV's real sample photographs (``data/real``, 13 views each) the residuals are 1.7-2.0x the
model-free corner noise (neighbouring corners share their error: the print, the lens and the
detector leave a pattern the model does not absorb), and the noise model is 2-4x too small:

=================  ===================  ===================  ===================  ===================
 fx fy cx cy        noise model          x fit/noise          CR2 sandwich         the kit (below)
=================  ===================  ===================  ===================  ===================
 left / jackknife   0.56 0.58 0.26 0.45  1.15 1.19 0.54 0.91  0.90 0.91 0.98 0.97  0.94 0.96 0.98 0.97
 right / jackknife  0.43 0.49 0.34 0.50  0.75 0.84 0.59 0.87  0.85 0.83 0.98 0.90  0.86 0.86 0.99 0.92
 6 synthetic views  0.94 1.01 1.25 1.01  1.02 1.10 1.35 1.09  0.78 0.85 1.19 0.85  1.08 1.17 1.53 1.18
 13 synthetic       0.94 0.95 1.04 0.91  0.97 0.99 1.08 0.94  0.89 0.91 0.93 0.93  1.10 1.11 1.16 1.08
=================  ===================  ===================  ===================  ===================

(real rows: divided by the brute-force jackknife; synthetic rows: the mean estimate divided by the true
spread over 25 noise draws.) Inflating the noise model by the ratio of the residual to the corner
noise misses cx by 2x on real photographs.

So the kit reports (:func:`honest_intrinsic_covariance`) the **larger of the noise model and the
CR2 sandwich in every direction** (merged by their generalised eigenvalues): never less than the
noise model, and as much as the views disagree. Below :data:`MIN_ROBUST_VIEWS` (4) views the
views cannot say how much they disagree and the noise model is used alone (the verdict then says
the views are too few). The method in words travels with the result
(``CalibrationResult.std_method``).

The projection uncertainty (:func:`projection_covariance`) propagates the full covariance (the
intrinsics' honest one and each pose's conditional ``sigma^2 C_v^-1``) through the Jacobian of a
projection; the pose part of that Jacobian is linear in the point, so the sums over the views are
taken once: ``O(V + M)`` time and memory for ``M`` pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["NormalBlocks", "honest_intrinsic_covariance", "projection_covariance", "rodrigues",
           "robust_intrinsic_covariance", "ray_rotation_covariance", "MIN_ROBUST_VIEWS", "METHOD_ROBUST",
           "METHOD_NOISE_MODEL"]

#: fewer views than this: the noise model alone (leaving one of 3 views out leaves too few for Zhang's method).
#: From 4 views on the sandwich is used although a spread over V views is itself known only to about
#: 1 / sqrt(2 (V - 1)) (41 % at 4 views): the noise model alone is worse, 2-4x too small on real photographs.
#: benchmarks/bench_sigma_views.py, 30 random subsets of OpenCV's real photographs per camera: +-1 sigma covers
#: the 13-view value in 48 / 43 % (left, 4 / 5 views) and 34 / 50 % (right) with the noise model alone,
#: 79 / 78 % and 67 / 78 % with the sandwich (honest: about 68 %; issue 21's acceptance 55-85 %)
MIN_ROBUST_VIEWS = 4
METHOD_ROBUST = ("the larger, in every direction, of the corner-noise model sigma^2 (J^T J)^-1 and a sandwich "
                 "over the {V} views (Bell-McCaffrey CR2, close to a leave-one-view-out jackknife)")
METHOD_NOISE_MODEL = ("the noise model's covariance sigma^2 (J^T J)^-1 only: {why}")


@dataclass
class NormalBlocks:
    """The normal equations ``J^T J`` of a calibration at its solution, block by block (``O(V)`` memory).

    A : (n, n) intrinsic block ``sum_v Ji_v^T Ji_v``
    B : (V, n, 6) ``Ji_v^T Je_v``
    C : (V, 6, 6) ``Je_v^T Je_v``
    A_views : (V, n, n) each view's share of ``A``
    g : (V, n) each view's intrinsic gradient ``Ji_v^T r_v``
    sigma2 : residual variance per coordinate, ``|r|^2 / (2N - p)``
    names : the intrinsic parameters, in order (``fx, fy, cx, cy, [skew], k1, ...``)
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    A_views: np.ndarray
    g: np.ndarray
    sigma2: float
    names: list

    @property
    def n_views(self) -> int:
        return len(self.C)

    def pose_coupling(self) -> np.ndarray:
        """``C_v^-1 B_v^T`` (V, 6, n): how each pose follows a change of the intrinsics (with a minus)."""
        return np.linalg.solve(self.C, self.B.transpose(0, 2, 1))

    def schur_views(self) -> np.ndarray:
        """Each view's share ``S_v = A_v - B_v C_v^-1 B_v^T`` (V, n, n) of the Schur complement."""
        return self.A_views - self.B @ self.pose_coupling()

    def schur(self) -> np.ndarray:
        """``S = A - sum_v B_v C_v^-1 B_v^T`` (n, n): the information on the intrinsics, poses eliminated."""
        return self.A - np.einsum("vij,vjk->ik", self.B, self.pose_coupling())


def _psd_max(P: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """The smallest-in-spirit covariance that is at least ``P`` and at least ``Q`` in every direction.

    With ``P = L L^T``: the eigenvalues ``l`` of ``L^-1 Q L^-T`` are replaced by ``max(l, 1)``.
    ``P`` must be positive definite; ``Q`` positive semi-definite.
    """
    L = np.linalg.cholesky(P)
    Li = np.linalg.inv(L)
    M = Li @ Q @ Li.T
    lam, U = np.linalg.eigh(0.5 * (M + M.T))
    T = L @ U
    return (T * np.maximum(lam, 1.0)) @ T.T


def robust_intrinsic_covariance(blocks: NormalBlocks) -> np.ndarray | None:
    """The CR2 sandwich over views (module docstring), (n, n); ``None`` when leaving a view out leaves
    the intrinsics undetermined (one view alone determines part of the lens)."""
    Sv = blocks.schur_views()
    S = Sv.sum(axis=0)
    w, U = np.linalg.eigh(0.5 * (S + S.T))
    if w.min() <= 0:
        return None
    Li = (U / np.sqrt(w)) @ U.T  # S^-1/2
    lam, Q = np.linalg.eigh(np.eye(len(S))[None] - Li[None] @ Sv @ Li[None])  # I - S^-1/2 S_v S^-1/2
    if lam.min() <= 1e-9:
        return None
    u = np.einsum("vij,vj->vi", (Q / np.sqrt(lam)[:, None, :]) @ Q.transpose(0, 2, 1), blocks.g @ Li)
    d = u @ Li  # (V, n): S^-1/2 (I - S^-1/2 S_v S^-1/2)^-1/2 S^-1/2 g_v
    return d.T @ d


def honest_intrinsic_covariance(blocks: NormalBlocks) -> tuple[np.ndarray, np.ndarray, str]:
    """``(covariance, noise-model covariance, method in words)`` of the intrinsics.

    The covariance is the larger of the noise model's and the views' CR2 sandwich in every direction
    (module docstring); with fewer than :data:`MIN_ROBUST_VIEWS` views, or when leaving one view
    out leaves the intrinsics undetermined, the noise model's alone.
    """
    noise = blocks.sigma2 * np.linalg.inv(blocks.schur())
    V = blocks.n_views
    if V < MIN_ROBUST_VIEWS:
        return noise, noise, METHOD_NOISE_MODEL.format(
            why=f"{V} views are too few to measure how much they disagree (at least {MIN_ROBUST_VIEWS})")
    robust = robust_intrinsic_covariance(blocks)
    if robust is None or not np.all(np.isfinite(robust)):
        return noise, noise, METHOD_NOISE_MODEL.format(
            why="one view alone determines part of the lens, so the views' disagreement cannot be measured")
    try:
        cov = _psd_max(noise, robust)
    except np.linalg.LinAlgError:
        return noise, noise, METHOD_NOISE_MODEL.format(why="the noise model's covariance is singular")
    return cov, noise, METHOD_ROBUST.format(V=V)


def projection_covariance(blocks: NormalBlocks, cov_intrinsics: np.ndarray, dq_dintr: np.ndarray,
                          dq_dP: np.ndarray, P: np.ndarray, omegas: np.ndarray,
                          tvecs: np.ndarray | None) -> np.ndarray:
    """Covariance (M, 2, 2) of the projections of M points held fixed in the boards' frames ("mean frames").

    The point ``P`` (camera frame) is mapped into every board's frame with the solved poses, back with
    perturbed ones and averaged; its projection moves with the intrinsics (``dq_dintr``) and, through
    the averaged point (``dq_dP``), with every pose. Moving board ``v``'s rotation parameter ``k``
    moves the average by ``[w_vk]_x (P - t_v) / V`` (``[w_vk]_x = dR_v/dr_k R_v^T``), its
    translation by ``I / V``. So the pose Jacobian is linear in the point,
    ``D_v(P) = ([P]_x L_v + N_v) / V`` with ``L_v = [-W_v, 0]`` and ``N_v = [[t_v]_x W_v, I]``, and
    every sum over the views is a 3x3 or 3xn matrix computed once: ``O(V + M)`` time and memory.

    The full parameter covariance is ``W Sigma W^T + sigma^2 blockdiag(0, C_v^-1)`` with ``Sigma`` the
    intrinsics' covariance and ``W = [I; -C_v^-1 B_v^T]`` (the poses follow the intrinsics), the
    exact block form of ``sigma^2 (J^T J)^-1`` when ``Sigma`` is the noise model's. For
    ``G = [G_I, G_v]``::

        G C G^T = (G_I - sum_v G_v C_v^-1 B_v^T) Sigma (...)^T + sigma^2 sum_v G_v C_v^-1 G_v^T

    Parameters
    ----------
    blocks : NormalBlocks of the calibration;  cov_intrinsics : (n, n)
    dq_dintr : (M, 2, n) Jacobian of the projections with respect to the intrinsics
    dq_dP : (M, 2, 3) Jacobian of the projections with respect to the (camera-frame) point
    P : (M, 3) the points, camera frame
    omegas : (V, 3, 3) ``W_v``, column k the axis of ``dR_v/dr_k R_v^T``
    tvecs : (V, 3) board translations; ``None`` for points at infinity (directions: the translations
        do not move them)
    """
    LK, NK, LCL, LCN, NCN = _pose_sums(blocks, omegas, tvecs)
    X = _skew_matrices(np.asarray(P, dtype=np.float64))  # (M, 3, 3)
    GW = dq_dintr - dq_dP @ (X @ LK + NK)
    XLCN = X @ LCN
    pose3 = X @ LCL @ X.transpose(0, 2, 1) + XLCN + XLCN.transpose(0, 2, 1) + NCN  # (M, 3, 3)
    return GW @ cov_intrinsics @ GW.transpose(0, 2, 1) + blocks.sigma2 * (dq_dP @ pose3 @ dq_dP.transpose(0, 2, 1))


def _pose_sums(blocks: NormalBlocks, omegas: np.ndarray, tvecs: np.ndarray | None):
    """The sums over the views of :func:`projection_covariance`: ``L K``, ``N K`` (3, n) and ``L C^-1 L^T``,
    ``L C^-1 N^T``, ``N C^-1 N^T`` (3, 3), each divided by ``V`` per pose Jacobian."""
    V = blocks.n_views
    Kc = blocks.pose_coupling()  # (V, 6, n)
    Cinv = np.linalg.inv(blocks.C)
    L = np.zeros((V, 3, 6))
    L[:, :, :3] = -omegas
    N = np.zeros((V, 3, 6))
    if tvecs is not None:
        N[:, :, :3] = _skew_matrices(np.asarray(tvecs, dtype=np.float64)) @ omegas
        N[:, :, 3:] = np.eye(3)
    LC, NC = L @ Cinv, N @ Cinv
    LK, NK = (L @ Kc).sum(axis=0) / V, (N @ Kc).sum(axis=0) / V  # (3, n)
    LCL = (LC @ L.transpose(0, 2, 1)).sum(axis=0) / V ** 2
    LCN = (LC @ N.transpose(0, 2, 1)).sum(axis=0) / V ** 2
    NCN = (NC @ N.transpose(0, 2, 1)).sum(axis=0) / V ** 2
    return LK, NK, LCL, LCN, NCN


def ray_rotation_covariance(blocks: NormalBlocks, cov_intrinsics: np.ndarray, omegas: np.ndarray) -> np.ndarray:
    """(n + 3, n + 3) joint covariance of the intrinsics and of a small rotation ``r`` of the camera's rays
    (``v -> v + r x v``) that carries :func:`projection_covariance` at infinity in ``n + 3`` numbers.

    At infinity the poses move a projection only through the mean rotation of the boards' frames,
    ``dP = [P]_x dw`` with ``dw = -L K dI + xi``, ``cov(xi) = sigma^2 L C^-1 L^T`` (the sums of
    :func:`_pose_sums`). With ``r = -dw``, the Jacobian ``J = [dq/dI, -dq/dP [v]_x]`` of a projection of the
    ray ``v`` and this covariance give ``J cov J^T`` equal to :func:`projection_covariance` with
    ``tvecs=None``: what a calibration file needs to carry for the projection uncertainty of directions
    (:mod:`dtscal_lib.file_uncertainty`), without its views.
    """
    LK, _, LCL, _, _ = _pose_sums(blocks, omegas, None)
    n = len(cov_intrinsics)
    out = np.zeros((n + 3, n + 3))
    out[:n, :n] = cov_intrinsics
    out[n:, :n] = LK @ cov_intrinsics
    out[:n, n:] = out[n:, :n].T
    out[n:, n:] = LK @ cov_intrinsics @ LK.T + blocks.sigma2 * LCL
    return 0.5 * (out + out.T)


# --------------------------------------------------------------------------- rotations
def _skew_matrices(v: np.ndarray) -> np.ndarray:
    """``[v]_x`` for each row of ``v`` (M, 3): (M, 3, 3)."""
    S = np.zeros((len(v), 3, 3))
    S[:, 0, 1], S[:, 0, 2], S[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    S[:, 1, 0], S[:, 2, 0], S[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return S


def rodrigues(rvecs: np.ndarray, jacobian: bool = True):
    """Rotation matrices of Rodrigues vectors (V, 3) -> (V, 3, 3), and ``dR[v, k] = dR / d r_k`` (V, 3, 3, 3).

    Vectorized ``cv2.Rodrigues`` (the same matrices and derivatives, checked in the tests); the
    derivative is Gallego and Yezzi's ``dR/dr_k = (r_k [r]_x + [r x (I - R) e_k]_x) R / |r|^2``, and
    its first-order limit ``[e_k]_x`` near the identity.
    """
    r = np.asarray(rvecs, dtype=np.float64).reshape(-1, 3)
    th = np.linalg.norm(r, axis=1)
    small = th < 1e-9
    ths = np.where(small, 1.0, th)
    k = r / ths[:, None]
    c, s = np.cos(th), np.sin(th)
    Kx = _skew_matrices(k)
    R = (c[:, None, None] * np.eye(3) + (1.0 - c)[:, None, None] * k[:, :, None] * k[:, None, :]
         + s[:, None, None] * Kx)
    if small.any():
        R[small] = np.eye(3) + _skew_matrices(r[small])
    if not jacobian:
        return R, None
    E = np.eye(3)
    rx = _skew_matrices(r)
    ImR = np.eye(3) - R  # (V, 3, 3); column k is (I - R) e_k
    dR = np.empty((len(r), 3, 3, 3))
    for j in range(3):
        w = np.cross(r, ImR[:, :, j])
        dR[:, j] = (r[:, j, None, None] * rx + _skew_matrices(w)) @ R / (ths ** 2)[:, None, None]
    if small.any():
        dR[small] = _skew_matrices(E)[None]
    return R, dR
