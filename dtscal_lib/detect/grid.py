"""The grid checks of a found board: local homographies, the quadratic through 8 neighbours, the smooth
(cubic) grid, and the sentence naming a corner that is off."""

from __future__ import annotations

import functools

import numpy as np

from ..boards import DUCKIETOWN_BOARD, Board
from ..limits import GRID_TOLERANCE_FRACTION, GRID_TOLERANCE_PX, SMOOTH_GRID_TOLERANCE


def _neighbour_vectors(corners: np.ndarray, board: Board):
    """Vectors from each corner to its four grid neighbours, NaN where there is none.

    Returns ``(right, left, down, up)``, each ``(rows, cols, 2)``: right = to corner (j, i+1),
    left = to (j, i-1), down = to (j+1, i), up = to (j-1, i).
    """
    g = np.asarray(corners, dtype=np.float64).reshape(board.rows, board.cols, 2)
    nan = np.full_like(g, np.nan)
    right, left, down, up = nan.copy(), nan.copy(), nan.copy(), nan.copy()
    dx, dy = np.diff(g, axis=1), np.diff(g, axis=0)
    right[:, :-1], left[:, 1:] = dx, -dx
    down[:-1], up[1:] = dy, -dy
    return right, left, down, up



def grid_disagreement(corners: np.ndarray, board: Board = DUCKIETOWN_BOARD) -> np.ndarray:
    """Distance of each corner from where its neighbours' local homography puts it.

    For each corner, a homography from board indices to pixels is fitted (DLT) to the
    corners within two rows and columns of it, itself left out, and evaluated at the
    corner's own index. A flat board seen through a smooth lens is locally a homography,
    so a true corner agrees to a small fraction of a pixel; a corner pulled by an edge or
    clutter does not.

    Parameters
    ----------
    corners : (N, 2) pixels, board row-major order

    Returns
    -------
    (N,) float64 pixels (NaN for a corner with fewer than 5 neighbours)
    """
    return _grid_prediction(corners, board)[1]


def _grid_prediction(corners: np.ndarray, board: Board, exclude: np.ndarray | None = None):
    """(predicted (N, 2) pixels, distance (N,)) from the local homographies.

    Inner corners are predicted from their 8 neighbours (the 3x3 block around them), corners on
    the outer ring of the grid from the 5x5 block (8 or 14 neighbours). ``exclude``d corners are
    not used as neighbours.
    """
    c = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    pred, err = np.full_like(c, np.nan), np.full(len(c), np.nan)
    for reach in (1, 2):
        p, e, n = _local_homography(c, board, reach, exclude)
        use = np.isnan(err) & (n >= (8 if reach == 1 else 6))
        pred[use], err[use] = p[use], e[use]
    return pred, err


def _local_homography(c: np.ndarray, board: Board, reach: int, exclude: np.ndarray | None,
                      only: np.ndarray | None = None):
    """Per-corner DLT from index offsets within ``reach`` to pixels; (pred, err, n_neighbours).

    ``only`` (bool (N,)): predict these corners only (the others get NaN and 0 neighbours)."""
    R, C = board.rows, board.cols
    if only is not None:
        sel = np.flatnonzero(only)
        pred, err, n = np.full_like(c, np.nan), np.full(len(c), np.nan), np.zeros(len(c), dtype=int)
        if len(sel):
            pred[sel], err[sel], n[sel] = _local_homography_at(c, board, reach, exclude, sel)
        return pred, err, n
    return _local_homography_at(c, board, reach, exclude, np.arange(R * C))


@functools.lru_cache(maxsize=4)
def _offsets(reach: int):
    """Index offsets ``(dj, di)`` within ``reach`` (the centre left out), and the products ``P P^T`` of
    ``P = (di, dj, 1)`` for each, flattened ``(K, 9)``: the blocks of a DLT's normal matrix."""
    offs = np.array([(dj, di) for dj in range(-reach, reach + 1) for di in range(-reach, reach + 1)
                     if (dj, di) != (0, 0)])
    P = np.column_stack([offs[:, 1], offs[:, 0], np.ones(len(offs))]).astype(np.float64)
    return offs, (P[:, :, None] * P[:, None, :]).reshape(-1, 9)


def _local_homography_at(c: np.ndarray, board: Board, reach: int, exclude: np.ndarray | None, targets: np.ndarray):
    """:func:`_local_homography` for the corners ``targets`` (indices): (pred, err, n), each for those only."""
    R, C = board.rows, board.cols
    j, i = np.divmod(targets, C)
    offs, PP = _offsets(reach)
    nj, ni = j[:, None] + offs[:, 0], i[:, None] + offs[:, 1]
    valid = (nj >= 0) & (nj < R) & (ni >= 0) & (ni < C)
    nb = np.where(valid, nj * C + ni, 0)
    if exclude is not None:
        valid &= ~np.asarray(exclude, dtype=bool)[nb]
    n = valid.sum(1)
    # pixel coordinates relative to the neighbours' mean, scaled to about 1 (conditioning)
    p = c[nb]
    wt = valid.astype(np.float64)
    centre = np.einsum("tk,tkd->td", wt, p) / np.maximum(n, 1)[:, None]
    q = p - centre[:, None]
    scale = np.maximum(np.sqrt(np.einsum("tk,tkd,tkd->t", wt, q, q) / np.maximum(n, 1)), 1e-9)
    q /= scale[:, None, None]
    u, v = q[..., 0], q[..., 1]
    # the DLT's normal matrix A^T A, with the rows (x, y, 1, 0, 0, 0, -u x, -u y, -u) and
    # (0, 0, 0, x, y, 1, -v x, -v y, -v) of each valid neighbour, in 3x3 blocks of sums of P P^T
    # (P = (x, y, 1)) weighted by 1, -u, -v and u^2 + v^2
    s1, su, sv, suv = (w @ PP for w in (wt, wt * u, wt * v, wt * (u * u + v * v)))
    M = np.zeros((len(targets), 9, 9))
    M[:, 0:3, 0:3] = M[:, 3:6, 3:6] = s1.reshape(-1, 3, 3)
    M[:, 0:3, 6:9] = -su.reshape(-1, 3, 3)
    M[:, 3:6, 6:9] = -sv.reshape(-1, 3, 3)
    M[:, 6:9, 0:3] = M[:, 0:3, 6:9].transpose(0, 2, 1)
    M[:, 6:9, 3:6] = M[:, 3:6, 6:9].transpose(0, 2, 1)
    M[:, 6:9, 6:9] = suv.reshape(-1, 3, 3)
    # least squares with the homography's last element fixed to 1 (the neighbours' centre maps to a
    # finite point): an 8x8 solve per corner, ten times faster than the null vector by eigh; a tiny
    # ridge keeps corners with too few neighbours (n < 4, no prediction) from making it singular
    ridge = 1e-12 * (np.trace(M, axis1=1, axis2=2)[:, None, None] + 1.0) * np.eye(8)
    h = np.linalg.solve(M[:, :8, :8] + ridge, -M[:, :8, 8:9])[..., 0]
    # evaluate at the corner's own index, offset (0, 0)
    ok = n >= 4
    pred = np.full((len(targets), 2), np.nan)
    pred[ok] = h[ok][:, [2, 5]] * scale[ok, None] + centre[ok]
    return pred, np.linalg.norm(pred - c[targets], axis=1), n


def _local_square(corners: np.ndarray, board: Board) -> np.ndarray:
    right, left, down, up = _neighbour_vectors(corners, board)
    lens = np.stack([np.linalg.norm(v, axis=-1) for v in (right, left, down, up)], axis=-1)
    return np.nanmin(lens, axis=-1).ravel()



def _outer_ring(board: Board) -> np.ndarray:
    """(N,) bool: corners in the first or last row or column of the grid."""
    j, i = np.divmod(np.arange(board.n_corners), board.cols)
    return (j == 0) | (j == board.rows - 1) | (i == 0) | (i == board.cols - 1)


def _jump_weights():
    """Weights of the quadratic-through-8-neighbours check for each place of a corner in a 3x3 block.

    ``{(r, c): (w (9,), gain)}``: ``w @ block`` (the block's 9 corners, row-major) is the prediction
    of corner ``(r, c)`` by the least-squares quadratic in the indices through the other 8, minus
    the corner itself (``w[r*3 + c] = -1``); ``gain`` is the norm of ``w``, the factor by which
    independent corner noise grows in it (1.5 at the centre and at the middle of a side, 2.27 at
    a corner of the block, where the quadratic extrapolates).
    """
    pts = [(r, c) for r in range(3) for c in range(3)]

    def row(p):
        r, c = p
        return [1.0, c, r, c * c, c * r, r * r]
    out = {}
    for t in pts:
        others = [p for p in pts if p != t]
        w = np.zeros(9)
        w[[pts.index(p) for p in others]] = np.array(row(t)) @ np.linalg.pinv(np.array([row(p) for p in others]))
        w[pts.index(t)] = -1.0
        out[t] = (w, float(np.linalg.norm(w)))
    return out


_JUMP_WEIGHTS = _jump_weights()
#: the noise gain of the check at an inner corner (the reference of :data:`GRID_TOLERANCE_PX`)
_CENTRE_GAIN = _JUMP_WEIGHTS[(1, 1)][1]


def _grid_jumps(corners: np.ndarray, board: Board) -> tuple[np.ndarray, np.ndarray]:
    """``(jump vectors (N, 2), noise gain (N,))`` of :func:`grid_jump`; zeros for boards under 3x3."""
    W, gain = _grid_jump_matrix(board.rows, board.cols)
    return W @ np.asarray(corners, dtype=np.float64).reshape(-1, 2), gain.copy()


@functools.lru_cache(maxsize=32)
def _grid_jump_matrix(R: int, C: int) -> tuple[np.ndarray, np.ndarray]:
    """``(W (N, N), gain (N,))``: the jump vectors of :func:`_grid_jumps` are ``W @ corners`` (one product
    instead of a Python loop over the outer ring: the same weights, summed in another order)."""
    N = R * C
    W, gain = np.zeros((N, N)), np.full(N, _CENTRE_GAIN)
    if R < 3 or C < 3:
        return W, gain
    for j in range(R):
        for i in range(C):
            # an inner corner: the centre of its own 3x3 block; the outer ring: the block reaching inward
            j0, i0 = min(max(j - 1, 0), R - 3), min(max(i - 1, 0), C - 3)
            w, gn = _JUMP_WEIGHTS[(j - j0, i - i0)]
            block = ((j0 + np.arange(3))[:, None] * C + (i0 + np.arange(3))[None, :]).ravel()
            W[j * C + i, block] = w
            gain[j * C + i] = gn
    return W, gain


def grid_jump(corners: np.ndarray, board: Board = DUCKIETOWN_BOARD) -> np.ndarray:
    """Distance (pixels) of each corner from the quadratic through its 8 grid neighbours.

    The least-squares quadratic in the corner indices through the 3x3 block without its centre
    predicts the centre as ``0.5 * (sum of the 4 edge neighbours) - 0.25 * (sum of the 4 diagonal
    ones)``: exact for any grid that is a cubic in the indices (perspective, lens distortion and a
    print's smooth curl, locally), so a smoothly bent board passes, while a corner displaced by
    ``d`` is off by ``d`` (its neighbours by at most ``d / 2``). Independent corner noise of
    ``sigma`` per coordinate gives a prediction error of ``1.5 sigma`` per coordinate (the
    weights' norm), as in :func:`dtscal_lib.quality.corner_noise`. A corner of the outer ring is
    predicted by the quadratic through the other 8 corners of the 3x3 block reaching inward from
    it (noise gain 1.5 in the middle of a side, 2.27 at the board's corners).

    Returns
    -------
    (N,) float64 pixels (zeros for boards with fewer than 3 rows or columns)

    >>> from dtscal_lib.boards import parse_board
    >>> b = parse_board("4x3")
    >>> g = np.mgrid[0:3, 0:4][::-1].transpose(1, 2, 0).reshape(-1, 2) * 30.0
    >>> g = g + 0.002 * g ** 2  # a smooth bend
    >>> bool(grid_jump(g, b).max() < 1e-9)
    True
    >>> g[5] += (1.5, 0.0)
    >>> grid_jump(g, b).reshape(3, 4)[1].round(2).tolist()
    [0.75, 1.5, 0.75, 0.75]
    """
    return np.linalg.norm(_grid_jumps(corners, board)[0], axis=1)


def grid_tolerance(corners: np.ndarray, board: Board = DUCKIETOWN_BOARD) -> np.ndarray:
    """(N,) pixels: the largest :func:`grid_jump` a true corner may show (see :data:`GRID_TOLERANCE_PX`),
    grown with the check's noise gain on the board's corners (x 2.27 / 1.5)."""
    gain = _grid_jumps(corners, board)[1]
    base = np.maximum(GRID_TOLERANCE_PX, GRID_TOLERANCE_FRACTION * _local_square(corners, board))
    return base * gain / _CENTRE_GAIN


def _inner_disagreement(c: np.ndarray, board: Board) -> np.ndarray:
    """Distance from the quadratic through the 8 neighbours (:func:`grid_jump`), every corner."""
    return grid_jump(c, board)


def _grid_design(board: Board) -> np.ndarray | None:
    """Design matrix of a 2-D polynomial in the corner indices (cubic, or quadratic for small boards)."""
    return _grid_design_cached(board.rows, board.cols)[0]


@functools.lru_cache(maxsize=32)
def _grid_design_cached(rows: int, cols: int):
    """(design matrix or None, its pseudo-inverse or None) of a ``rows x cols`` grid: see :func:`_grid_design`."""
    board = Board(cols=cols, rows=rows, square=1.0)
    A = _grid_design_matrix(board)
    return A, (None if A is None else np.linalg.pinv(A))


def _grid_design_matrix(board: Board) -> np.ndarray | None:
    j, i = np.mgrid[0:board.rows, 0:board.cols]
    u = i.ravel() / max(board.cols - 1, 1)
    v = j.ravel() / max(board.rows - 1, 1)
    cols = [np.ones_like(u), u, v]
    degree = 3 if min(board.cols, board.rows) >= 4 else 2 if min(board.cols, board.rows) >= 3 else 1
    if degree >= 2:
        cols += [u * u, u * v, v * v]
    if degree >= 3:
        cols += [u ** 3, u * u * v, u * v * v, v ** 3]
    A = np.column_stack(cols)
    return A if len(A) >= len(cols) + 4 else None


def grid_residuals(corners: np.ndarray, board: Board = DUCKIETOWN_BOARD,
                   threshold: float = SMOOTH_GRID_TOLERANCE) -> np.ndarray:
    """Distance of each corner from a smooth grid through the others, in units of the smallest spacing.

    The image of a flat board's corner grid, through perspective and a smooth lens, is
    a smooth function of the corner indices ``(i, j)``: a cubic polynomial in ``(i, j)``
    fits true corners to within 0.08 of the smallest corner spacing (worst of 1500 random
    Duckiebot poses, 0.18-1.3 m, tilts up to 57 degrees). The fit is made robust by
    leaving out, one at a time, the worst corner while it is off by more than
    ``threshold``; every corner's residual is then measured against the final fit.

    Parameters
    ----------
    corners : (N, 2) pixels, board row-major order

    Returns
    -------
    (N,) float64 residual / smallest neighbour spacing (zeros for boards too small to check)
    """
    return _robust_grid_fit(corners, board, threshold)[1]


def _robust_grid_fit(corners: np.ndarray, board: Board, threshold: float):
    """(fitted (N, 2) pixels, residual (N,) in smallest spacings); see :func:`grid_residuals`."""
    c = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    A = _grid_design(board)
    if A is None:
        return c.copy(), np.zeros(len(c))
    g = c.reshape(board.rows, board.cols, 2)
    spacing = max(1e-9, float(min(np.linalg.norm(np.diff(g, axis=1), axis=2).min(),
                                  np.linalg.norm(np.diff(g, axis=0), axis=2).min())))
    inlier = np.ones(len(c), dtype=bool)
    coef = _grid_design_cached(board.rows, board.cols)[1] @ c  # the fit through all corners
    for _ in range(len(c) // 4):
        res = np.linalg.norm(A @ coef - c, axis=1) / spacing
        worst = int(np.argmax(np.where(inlier, res, -1.0)))
        if res[worst] <= threshold or inlier.sum() <= A.shape[1] + 4:
            break
        inlier[worst] = False
        coef, *_ = np.linalg.lstsq(A[inlier], c[inlier], rcond=None)
    fitted = A @ coef
    return fitted, np.linalg.norm(fitted - c, axis=1) / spacing


def grid_rejection(corners: np.ndarray, board: Board = DUCKIETOWN_BOARD) -> str:
    """Why a found board's corners were rejected: the corner farthest off its grid, named.

    The corner with the largest :func:`grid_jump` relative to its :func:`grid_tolerance`, or, when
    every inner corner passes that check, the one farthest off the smooth (cubic) grid of the
    guard (:func:`grid_residuals`). Rows and columns count from 1 in the board's row-major order
    (:attr:`Detection.corners`).

    >>> from dtscal_lib.boards import parse_board
    >>> b = parse_board("4x3")
    >>> g = np.mgrid[0:3, 0:4][::-1].transpose(1, 2, 0).reshape(-1, 2) * 30.0
    >>> g[6] += (0.0, 4.0)
    >>> grid_rejection(g, b)
    'corner at row 2, column 3 (pixel 60.0, 34.0) is 4.00 px from where its 8 neighbours put it (tolerance 2.60 px)'
    """
    c = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    vec, _ = _grid_jumps(c, board)
    jump, tol = np.linalg.norm(vec, axis=1), grid_tolerance(c, board)
    k = int(np.argmax(jump / tol))
    if jump[k] > tol[k]:
        # a displaced corner also shifts its neighbours' predictions: name the one whose move onto its
        # neighbours' grid leaves the others closest to theirs
        best = np.inf
        for cand in np.flatnonzero(jump > 0.5 * tol):
            trial = c.copy()
            trial[cand] += vec[cand]
            rest = np.delete(grid_jump(trial, board) / tol, cand).max(initial=0.0)
            if rest < best - 1e-9:
                best, k = rest, int(cand)
        what, dist, limit = "from where its 8 neighbours put it", jump[k], tol[k]
    else:
        res = grid_residuals(c, board, SMOOTH_GRID_TOLERANCE)
        k = int(np.argmax(res))
        spacing = float(np.nanmin(_local_square(c, board)))
        what, dist, limit = "off the smooth grid through the other corners", res[k] * spacing, \
            SMOOTH_GRID_TOLERANCE * spacing
    j, i = divmod(k, board.cols)
    return (f"corner at row {j + 1}, column {i + 1} (pixel {c[k, 0]:.1f}, {c[k, 1]:.1f}) is {dist:.2f} px "
            f"{what} (tolerance {limit:.2f} px)")
