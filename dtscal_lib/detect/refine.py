"""Step 4: sub-pixel refinement that stays inside each corner's own squares, checked and polished."""

from __future__ import annotations

import math

import cv2
import numpy as np

from ..boards import DUCKIETOWN_BOARD, Board
from ..limits import SMOOTH_GRID_TOLERANCE
from .grid import (_grid_jumps, _inner_disagreement, _local_homography, _local_square, _neighbour_vectors,
                   _outer_ring, _robust_grid_fit, grid_residuals, grid_tolerance)

#: cornerSubPix stopping rule used by ROS: 30 iterations or a step below 0.1 px
SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.1)



def subpix_radius(corners: np.ndarray, board: Board = DUCKIETOWN_BOARD) -> int:
    """ROS's ``cornerSubPix`` window half-size: half the smallest neighbour spacing, at least 2 px."""
    grid = np.asarray(corners, dtype=np.float64).reshape(board.rows, board.cols, 2)
    along = np.linalg.norm(np.diff(grid, axis=1), axis=2).min()
    across = np.linalg.norm(np.diff(grid, axis=0), axis=2).min()
    return max(2, int(math.ceil(0.5 * min(along, across))))


def refine_corners(gray: np.ndarray, corners: np.ndarray, board: Board = DUCKIETOWN_BOARD) -> np.ndarray:
    """Sub-pixel corners with ``cv2.cornerSubPix``, window half-size :func:`subpix_radius`.

    Parameters
    ----------
    gray : (h, w) uint8
    corners : (N, 2) pixels, board row-major order

    Returns
    -------
    (N, 2) float64 pixels
    """
    r = subpix_radius(corners, board)
    pts = np.asarray(corners, dtype=np.float32).reshape(-1, 1, 2).copy()
    cv2.cornerSubPix(gray, pts, (r, r), (-1, -1), SUBPIX_CRITERIA)
    return pts.reshape(-1, 2).astype(np.float64)


#: the outermost squares of a real board may be cut narrow, carry a printed outline or end at the
#: board's edge: a corner on the outer ring of the grid assumes its outward squares are at least
#: this fraction of a full square wide
OUTER_SQUARE_FRACTION = 0.35
#: an inner corner's window reaches at most this fraction of the way to its squares' far edges
INNER_REACH = 0.7
#: and stays this many pixels short of any far edge (edge blur, start error of the detector)
WINDOW_MARGIN_PX = 1.5
#: an outer corner whose small window sees less isotropic gradients than this (corner_isotropy) is
#: refined with a window as big as an inner corner's (motion blur)
MIN_ISOTROPY = 0.4
#: smallest window half-size, pixels (smaller windows cannot pull in a start a pixel or two off on blurred
#: small boards)
MIN_WINDOW = 4
#: stopping rule of the kit's refinement: 30 iterations or a step below 0.01 px (ROS: 30, 0.1 px)
REFINE_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.01)
#: stopping rule of the first pass (ROS's 0.1 px): its corners are checked against tolerances of a pixel
#: and then polished (:func:`polish_corners`, which converges again) or, where the polish is not used,
#: finished with :data:`REFINE_CRITERIA`. Why: ``cornerSubPix`` contracts a start error about 20x per
#: iteration, so a 0.1 px step leaves about 0.005 px (benchmarks/README.md)
FIRST_PASS_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.1)
#: the kit's last refinement step works on the image smoothed by a Gaussian of this sigma, pixels
#: (see :func:`polish_corners`)
REFINE_SIGMA = 1.0
#: a corner that the smoothed step would move this far (pixels) or more keeps its unsmoothed position
POLISH_MAX_MOVE_PX = 0.1


def corner_windows(corners: np.ndarray, board: Board = DUCKIETOWN_BOARD, *,
                   outer_fraction: float = OUTER_SQUARE_FRACTION, margin: float | None = None) -> np.ndarray:
    """Per-corner ``cornerSubPix`` window half-size that stays inside the corner's own four squares.

    ``cornerSubPix`` treats every intensity edge in its (square, axis-aligned) window as an
    edge through the corner. The far edges of the corner's four squares, and anything beyond
    them (the board's physical edge, a printed outline, clutter), pull the estimate. The
    window half-size ``r`` is therefore limited, for each of the four sides, so that the
    window's reach toward that side's far edge, ``r (|n_x| + |n_y|)`` for the edge's unit
    normal ``n``, stays below the edge's distance times :data:`INNER_REACH`, minus
    ``margin``. On the outer ring of the grid the outward squares may be
    cut narrow: their far edge is assumed at :data:`OUTER_SQUARE_FRACTION` of the opposite
    square's width. The local geometry comes from the corner's neighbours, so perspective
    (near squares big, far squares small) gives each corner its own window.

    Parameters
    ----------
    corners : (N, 2) pixels, board row-major order
    outer_fraction : assumed width of the outward squares of the outer ring, in squares
    margin : pixels the window stays short of a far edge (default :data:`WINDOW_MARGIN_PX`)

    Returns
    -------
    (N,) int window half-sizes, at least :data:`MIN_WINDOW`

    Examples
    --------
    >>> from dtscal_lib.boards import parse_board
    >>> b = parse_board("4x3")
    >>> grid = np.mgrid[0:3, 0:4][::-1].transpose(1, 2, 0).reshape(-1, 2) * 30.0 + 100
    >>> corner_windows(grid, b).reshape(3, 4)
    array([[ 9,  9,  9,  9],
           [ 9, 19, 19,  9],
           [ 9,  9,  9,  9]])
    """
    margin = WINDOW_MARGIN_PX if margin is None else float(margin)
    right, left, down, up = _neighbour_vectors(corners, board)

    def unit(a, b):
        v = np.where(np.isnan(a), b, a) + np.where(np.isnan(b), a, b)  # a, b point the same way
        return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-9)

    along = unit(right, -left)   # direction of the rows at each corner
    across = unit(down, -up)     # direction of the columns
    # the four sides at once: a side reached by stepping along `step` has its far edge parallel to `edge_dir`
    step = np.stack([right, left, down, up])
    opposite = np.stack([left, right, up, down])
    edge_dir = np.stack([across, across, along, along])
    normal = np.stack([-edge_dir[..., 1], edge_dir[..., 0]], axis=-1)
    support = np.abs(normal).sum(axis=-1)
    dist = np.abs((step * normal).sum(axis=-1))
    dist_opp = np.abs((opposite * normal).sum(axis=-1))
    reach = np.where(np.isnan(dist), outer_fraction * dist_opp, INNER_REACH * dist)
    room = ((reach - margin) / support).min(axis=0)
    return np.maximum(MIN_WINDOW, np.floor(room)).astype(int).ravel()


def _subpix(gray: np.ndarray, pts: np.ndarray, radius: np.ndarray, criteria=REFINE_CRITERIA) -> np.ndarray:
    """``cornerSubPix`` of each point with its own window half-size (grouped by size)."""
    out = np.asarray(pts, dtype=np.float64).reshape(-1, 2).copy()
    h, w = gray.shape[:2]
    out = np.clip(out, 0.0, [w - 1.0, h - 1.0])  # cornerSubPix needs its start inside the image
    for r in np.unique(radius):
        sel = radius == r
        p = out[sel].astype(np.float32).reshape(-1, 1, 2).copy()
        cv2.cornerSubPix(gray, p, (int(r), int(r)), (-1, -1), criteria)
        out[sel] = p.reshape(-1, 2)
    return out



def refine_image(gray: np.ndarray, corners: np.ndarray, reach: float, sigma: float | None = None) -> np.ndarray:
    """The image of :func:`polish_corners`: float32, smoothed by a Gaussian of ``sigma`` pixels
    (default :data:`REFINE_SIGMA`) within ``reach`` pixels of the corners' bounding box, as is elsewhere."""
    img = gray.astype(np.float32)
    sigma = REFINE_SIGMA if sigma is None else float(sigma)
    if sigma <= 0:
        return img
    h, w = img.shape
    pad = int(math.ceil(reach + 4.0 * sigma)) + 2
    pts = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    x0, y0 = np.clip(np.floor(pts.min(axis=0)).astype(int) - pad, 0, [w, h])
    x1, y1 = np.clip(np.ceil(pts.max(axis=0)).astype(int) + pad + 1, 0, [w, h])
    if x1 > x0 and y1 > y0:
        img[y0:y1, x0:x1] = cv2.GaussianBlur(img[y0:y1, x0:x1], (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    return img


def refine_corners_checked(gray: np.ndarray, corners: np.ndarray, board: Board = DUCKIETOWN_BOARD):
    """The kit's sub-pixel refinement: own-squares windows, then three checks.

    1. Every corner is refined with its :func:`corner_windows` half-size (an outer corner whose
       small window sees gradients in about one direction only, :func:`corner_isotropy` below
       :data:`MIN_ISOTROPY`, as under motion blur, with a window as big as an inner corner's);
       a corner that moved farther than half its local square (or its window) left its own
       squares and goes back to the detector's position.
    2. Each corner is compared with the quadratic through its 8 grid neighbours
       (:func:`grid_jump`); one off by more than :func:`grid_tolerance` (:data:`GRID_TOLERANCE_PX`
       or :data:`GRID_TOLERANCE_FRACTION` of its local square) is refined again, from the
       neighbours' prediction, with half the window. If it still disagrees the detection is
       unreliable (``ok`` False).
    3. The smooth-grid guard: a corner off the cubic grid through the others
       (:func:`grid_residuals` above :data:`SMOOTH_GRID_TOLERANCE`) goes back to the
       detector's position or the grid's refined prediction, whichever lies on the grid;
       otherwise ``ok`` is False.
    4. :func:`polish_corners`: once more on the smoothed image (corners refined with a grown
       window for motion blur are left as they are).

    The passes of step 1 stop at ROS's 0.1 px step (:data:`FIRST_PASS_CRITERIA`): their corners only
    meet tolerances of a pixel before the polish converges again to :data:`REFINE_CRITERIA`; a corner
    whose first-pass position is the answer (not polished) is converged to :data:`REFINE_CRITERIA`
    at the end. On ``data/real`` and the stress set the corners are as accurate as with 0.01 px
    throughout (stress set, seeds 0-9: median error 0.0203 px vs 0.0204, worst 0.125 px both).

    Returns
    -------
    (corners (N, 2) float64, ok: bool)
    """
    raw = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    radius = corner_windows(raw, board)
    grown = np.zeros(len(raw), dtype=bool)
    half = np.maximum(MIN_WINDOW, radius // 2)
    square = _local_square(raw, board)
    c = _subpix(gray, raw, radius, FIRST_PASS_CRITERIA)
    coarse = np.ones(len(raw), dtype=bool)  # still as the first pass left it (FIRST_PASS_CRITERIA)
    # the outer ring's windows are small and cannot pull in a start a few pixels off: where one
    # ended far from where the refined inner corners put it, start it again from there and keep
    # the answer that fits a corner better (corner_misfit)
    outer = _outer_ring(board)
    if outer.any() and (~outer).sum() >= 4:
        pred, _, n = _local_homography(c, board, 2, outer, only=outer)
        use = outer & (n >= 4) & np.all(np.isfinite(pred), axis=1)
        use[use] = np.linalg.norm(c[use] - pred[use], axis=1) > np.maximum(1.0, 0.25 * radius[use])
        if use.any():
            alt = _subpix(gray, pred[use], radius[use], FIRST_PASS_CRITERIA)
            idx = np.flatnonzero(use)
            misfit = corner_misfit(gray, np.concatenate([alt, c[idx]]), np.concatenate([radius[idx], radius[idx]]))
            better = misfit[:len(idx)] < misfit[len(idx):]
            idx = idx[better]
            c[idx] = alt[better]
            raw = raw.copy()
            raw[idx] = pred[idx]  # the start that was used
    # a small outer window on a motion-blurred corner sees edges in one direction only and cannot
    # locate it: there the window as big as an inner corner's is used (where it is bigger)
    if outer.any():
        sel = np.flatnonzero(outer)
        sel = sel[corner_isotropy(gray, c[sel], radius[sel]) < MIN_ISOTROPY]
        if len(sel):
            big_r = corner_windows(raw, board, outer_fraction=INNER_REACH)[sel]
            grow = big_r > radius[sel]
            sel, big_r = sel[grow], big_r[grow]
            if len(sel):
                c[sel] = _subpix(gray, raw[sel], big_r, FIRST_PASS_CRITERIA)
                radius = radius.copy()
                radius[sel] = big_r
                grown[sel] = True
    wandered = np.linalg.norm(c - raw, axis=1) > np.maximum(radius, 0.5 * square)
    c[wandered] = raw[wandered]
    coarse &= ~wandered
    tol = grid_tolerance(raw, board)
    bad = _inner_disagreement(c, board) > tol
    if bad.any():
        # predict the disagreeing corners from the others (their own positions are not trusted)
        pred = _local_homography(c, board, 1, bad, only=bad)[0][bad]
        quad = (c + _grid_jumps(c, board)[0])[bad]  # the outer ring's corners have too few neighbours there
        start = np.where(np.isfinite(pred), pred, quad)
        c[bad] = _subpix(gray, start, half[bad])
        coarse &= ~bad
        if np.any(_inner_disagreement(c, board) > tol):
            return c, False
    guarded = _guard_refinement(gray, raw, c, board, radius)
    if guarded is None:
        return c, False
    coarse &= np.all(guarded == c, axis=1)
    out, polished = _polish(gray, guarded, board, grown, None)
    finish = np.flatnonzero(coarse & ~polished)  # the first pass's answer stays: converge it fully
    if len(finish):
        out[finish] = _subpix(gray, out[finish], radius[finish])
    return out, True


def polish_corners(gray: np.ndarray, corners: np.ndarray, board: Board = DUCKIETOWN_BOARD, *,
                   skip: np.ndarray | None = None, sigma: float | None = None) -> np.ndarray:
    """Last step of the kit's refinement: ``cornerSubPix`` once more, on the smoothed image.

    ``cornerSubPix`` samples its window with bilinear interpolation at the sub-pixel position and
    differentiates with central differences. On sharp edges both depend on where an edge falls
    within a pixel, and the corner comes out off by a few hundredths of a pixel (0.03-0.06 px median
    on the stress set, the same with or without sensor noise). Smoothing the image with a Gaussian of
    :data:`REFINE_SIGMA` (:func:`refine_image`) does not move a checkerboard corner (the pattern is
    point-symmetric about it) but makes the edges smooth enough for both to be accurate.

    Each corner is refined again from where the checked refinement left it, with a window that stays
    ``sigma`` more short of its squares' far edges (the smoothing widens them:
    :func:`corner_windows` with ``margin = WINDOW_MARGIN_PX + sigma``). A polished corner that moved
    by :data:`POLISH_MAX_MOVE_PX` or more is not a small bias corrected but an ill-conditioned window
    (a small window on a heavily motion-blurred corner): it keeps its unsmoothed position, as do the
    corners in ``skip`` (refined with a grown window for motion blur).

    Parameters
    ----------
    gray : (h, w) uint8
    corners : (N, 2) pixels, board row-major order, already refined
    skip : optional (N,) bool, corners to leave as they are

    Returns
    -------
    (N, 2) float64 pixels
    """
    return _polish(gray, corners, board, skip, sigma)[0]


def _polish(gray: np.ndarray, corners: np.ndarray, board: Board, skip, sigma):
    """:func:`polish_corners`: (corners, (N,) bool: polished)."""
    sigma = REFINE_SIGMA if sigma is None else float(sigma)
    c = np.asarray(corners, dtype=np.float64).reshape(-1, 2).copy()
    if sigma <= 0:
        return c, np.zeros(len(c), dtype=bool)
    return _polish_points(gray, c, corner_windows(c, board, margin=WINDOW_MARGIN_PX + sigma), skip, sigma)


def _polish_points(gray: np.ndarray, corners: np.ndarray, radius: np.ndarray, skip=None, sigma=None):
    """The polish of :func:`polish_corners` with the windows given: (corners, (N,) bool: polished)."""
    sigma = REFINE_SIGMA if sigma is None else float(sigma)
    c = np.asarray(corners, dtype=np.float64).reshape(-1, 2).copy()
    # cornerSubPix reads 1 px beyond its window, bilinearly: the smoothing must be exact that far
    img = refine_image(gray, c, float(np.max(radius, initial=0)) + 3.0, sigma)
    p = _subpix(img, c, radius)
    use = np.linalg.norm(p - c, axis=1) < POLISH_MAX_MOVE_PX
    if skip is not None:
        use &= ~np.asarray(skip, dtype=bool)
    c[use] = p[use]
    return c, use


def _patches(img: np.ndarray, pts: np.ndarray, n: int) -> np.ndarray:
    """``(M, n, n)`` float32: ``cv2.getRectSubPix(img, (n, n), pt)`` of every point at once (``img`` float32).

    The same bilinear sampling (pixel ``(i, j)`` of a patch is the image at ``pt + (j, i) - (n - 1) / 2``),
    gathered for all points in one numpy step instead of one OpenCV call per point (faster:
    benchmarks/README.md). Points whose patch reaches past the
    image edge are sampled by ``getRectSubPix`` (it replicates the edge).
    """
    h, w = img.shape
    p = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
    origin = p - 0.5 * (n - 1)
    base = np.floor(origin).astype(np.intp)
    frac = origin - base
    inside = np.all((base >= 0) & (base + n < (w, h)), axis=1)
    out = np.empty((len(p), n, n), dtype=np.float32)
    if inside.any():
        blocks = np.lib.stride_tricks.sliding_window_view(img, (n + 1, n + 1))[base[inside, 1], base[inside, 0]]
        ax, ay = frac[inside, 0, None, None].astype(np.float32), frac[inside, 1, None, None].astype(np.float32)
        rows = blocks[:, :, :-1] + ax * (blocks[:, :, 1:] - blocks[:, :, :-1])  # along x, then along y
        out[inside] = rows[:, :-1] + ay * (rows[:, 1:] - rows[:, :-1])
    for k in np.flatnonzero(~inside):
        out[k] = cv2.getRectSubPix(img, (n, n), (float(p[k, 0]), float(p[k, 1])))
    return out


def _window_gradients(gray: np.ndarray, pts: np.ndarray, radius):
    """The image gradients around each point, for windows of half-size ``radius``, all points at once.

    Returns ``(gx, gy, d, inside)``: ``gx, gy`` ``(M, m, m)`` central differences of the sub-pixel centred
    patches (:func:`_patches`) on the ``m x m`` grid (``m = 2 max(radius) + 1``) of offsets ``d`` (pixels,
    ``(m,)``) from the point, and ``inside`` ``(M, m, m)`` bool, each point's own ``(2 radius + 1)``-square window.
    """
    radius = np.asarray(radius, dtype=int).reshape(-1)
    big = int(radius.max(initial=0))
    pts = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
    if gray.dtype == np.float32:
        patch = _patches(gray, pts, 2 * big + 3)
    else:  # float32 of the part of the image the patches cover (the image's edge stays the edge)
        h, w = gray.shape
        x0, y0 = np.clip(np.floor(pts.min(axis=0)).astype(int) - big - 3, 0, [w, h])
        x1, y1 = np.clip(np.ceil(pts.max(axis=0)).astype(int) + big + 4, 0, [w, h])
        crop = gray[y0:y1, x0:x1].astype(np.float32)
        patch = _patches(crop, pts - (x0, y0), 2 * big + 3)
    gx = 0.5 * (patch[:, 1:-1, 2:] - patch[:, 1:-1, :-2])
    gy = 0.5 * (patch[:, 2:, 1:-1] - patch[:, :-2, 1:-1])
    d = np.arange(-big, big + 1, dtype=np.float64)
    near = np.abs(d)[None, :] <= radius[:, None]  # (M, m)
    return gx, gy, d, near[:, :, None] & near[:, None, :]


def corner_misfit(gray: np.ndarray, points: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """How badly each point fails ``cornerSubPix``'s condition of a corner, 0 for a perfect one.

    At a true corner ``q`` every image gradient ``g`` at a pixel ``p`` of the window is
    orthogonal to ``p - q`` (edges run through the corner, flat areas have no gradient). The
    misfit is ``sum((g . (p - q))^2) / sum(|g|^2 |p - q|^2)`` over the window of half-size
    ``radius`` (pixels closer than 1 px to ``q`` left out): between 0 and 1.

    Parameters
    ----------
    gray : (h, w) uint8
    points : (M, 2) pixels
    radius : (M,) int window half-sizes

    Returns
    -------
    (M,) float64
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(pts) == 0:
        return np.ones(0)
    gx, gy, d, inside = _window_gradients(gray, pts, radius)
    px, py = np.meshgrid(d, d)
    inside &= (np.hypot(px, py) >= 1.0)
    gx, gy = gx * inside, gy * inside
    num = np.sum((gx * px + gy * py) ** 2, axis=(1, 2))
    den = np.sum((gx * gx + gy * gy) * (px * px + py * py), axis=(1, 2))
    return np.where(den > 0, num / np.maximum(den, 1e-300), 1.0)


def corner_isotropy(gray: np.ndarray, points: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Smaller over larger eigenvalue of the gradient structure tensor in each window (0..1).

    A corner has strong gradients in two directions (about 0.3-1); an edge, or a corner smeared
    by motion blur, in one direction only (near 0), where ``cornerSubPix`` is ill-conditioned.
    Takes and returns arrays as :func:`corner_misfit` does: (M,) float64 for M points.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(pts) == 0:
        return np.zeros(0)
    gx, gy, _, inside = _window_gradients(gray, pts, radius)
    gx, gy = gx * inside, gy * inside
    a, b, d = (gx * gx).sum((1, 2)), (gx * gy).sum((1, 2)), (gy * gy).sum((1, 2))
    half_tr, det = 0.5 * (a + d), a * d - b * b
    root = np.sqrt(np.maximum(half_tr ** 2 - det, 0.0))
    return np.where(half_tr > 0, (half_tr - root) / np.maximum(half_tr + root, 1e-300), 0.0)


def _guard_refinement(gray: np.ndarray, raw: np.ndarray, refined: np.ndarray, board: Board,
                      radius: np.ndarray, threshold: float = SMOOTH_GRID_TOLERANCE) -> np.ndarray | None:
    """Guard against bad corners on small or strongly foreshortened boards.

    A corner off the smooth grid through the others (:func:`grid_residuals` above
       ``threshold``) is replaced by the first of these that lies on the grid: the
       detector's position, or the grid's prediction refined by ``cornerSubPix``.

    Returns the corners, or None when some corner stays off the grid: the detection is then
    unreliable and is dropped rather than fed to a calibration.
    """
    c = refined.copy()
    fitted, res = _robust_grid_fit(c, board, threshold)
    bad = np.flatnonzero(res > threshold)
    if len(bad) == 0:
        return c
    guess = _subpix(gray, fitted[bad], radius[bad])
    for k, idx in enumerate(bad):
        for cand in (raw[idx], guess[k]):
            trial = c.copy()
            trial[idx] = cand
            if _robust_grid_fit(trial, board, threshold)[1][idx] <= threshold:
                c[idx] = cand
                break
    return c if not np.any(grid_residuals(c, board, threshold) > threshold) else None
