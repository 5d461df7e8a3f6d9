"""Step 3: the board's grid straight from a cluster's saddles (the classic detector is then not run)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..boards import Board
from .saddles import _Candidate


#: a saddle is taken as the lattice's next corner when it lies within this fraction of the step from where
#: the previous corner's local grid vectors predict it (perspective changes a step by a few percent from one
#: corner to the next; the edge saddles of narrow outer squares lie about half a step off: see _saddle_lattice)
LATTICE_REACH = 0.3
#: the ring test of :func:`_saddle_lattice`, on the saddles one grid step outside the window (all the frame's
#: saddles, not only the cluster's). A window of a bigger grid has true corners there; a board has the weaker
#: saddles of its printed edge (a single square's corner against the white margin) or none. The window is refused
#: when the board's weakest corner is below LATTICE_RING_RATIO times the ring's strongest saddle, or when on one
#: side of the ring at least LATTICE_RING_SIDE of the positions hold a saddle at least LATTICE_RING_STRONG times
#: the board's median corner strength. Why these values: no wrong-size window of OpenCV's real photographs passes
#: both rules, nearly every right one does (measurements: benchmarks/README.md, "The detector's measurements").
#: A refused window goes to the classic detector (slower; the refined corners then start from its corners).
LATTICE_RING_RATIO = 0.8
LATTICE_RING_SIDE = 0.6
LATTICE_RING_STRONG = 0.5


def _saddle_lattice(cand: _Candidate, board: Board, seen: dict | None = None) -> np.ndarray | None:
    """The board's inner corners straight from a cluster's saddles, or None (then the classic detector runs).

    Walks the grid from the saddle nearest the cluster's centre: each corner's two local grid vectors
    (from its own neighbours, so perspective and lens distortion are followed step by step) predict its
    four neighbours, and the saddle nearest each prediction, if within :data:`LATTICE_REACH` of a step,
    gets the neighbouring grid index. The walk gives up (None) on any contradiction: one saddle at two
    indices, or two saddles at one. The board is the fully occupied ``rows x cols`` window of indices whose
    weakest saddle is strongest; the saddles one step outside it must be clearly weaker (the printed board's
    edge, where a single square's corner meets the white margin, gives weaker saddles one step out; equally
    strong ones mean a window of a bigger grid: None; see :data:`LATTICE_RING_RATIO`).
    Corners come out in a row-major order of the board at the sub-pixel saddles' precision (``cand.fine``,
    about 0.1-0.2 px: :func:`_saddles`; the walk itself uses the peak pixels); :func:`_finish` orders,
    refines and checks them as it does the classic detector's, and where its checks fail the classic
    detector still runs.

    Why: it saves the classic detector's work on most views at no loss of accuracy (benchmarks/README.md).
    """
    pts = np.asarray(cand.saddles, dtype=np.float64)
    n = len(pts)
    if n < board.n_corners:
        return None
    k = min(7, n)
    _, nbr = cKDTree(pts).query(pts, k=k)
    nbr = nbr[:, 1:]
    # each saddle's neighbours as (dx, dy, index) from it, for the walk below (plain Python: a few hundred
    # small steps, where numpy's per-call cost would dominate)
    rel = [list(zip(*r)) for r in zip((pts[nbr, 0] - pts[:, 0, None]).tolist(),
                                      (pts[nbr, 1] - pts[:, 1, None]).tolist(), nbr.tolist())]
    # seed: the saddle nearest the centre of the strong half (a board corner, not an edge saddle)
    strength = cand.strength if cand.strength is not None else np.ones(n)
    strong = strength >= np.median(strength)
    centre = pts[strong].mean(axis=0)
    seed = int(np.argmin(np.linalg.norm(pts - centre, axis=1)))
    vec = pts[nbr[seed]] - pts[seed]  # nearest first
    length = np.linalg.norm(vec, axis=1)
    u = vec[0]
    cos = np.abs(vec[1:] @ u) / np.maximum(length[1:] * length[0], 1e-12)
    if len(cos) == 0 or cos.min() > 0.5:
        return None
    v = vec[1 + int(np.argmin(cos))]
    index = {seed: (0, 0)}
    at = {(0, 0): seed}
    local = {seed: (float(u[0]), float(u[1]), float(v[0]), float(v[1]))}
    queue = [seed]
    head = 0
    reach2 = LATTICE_REACH * LATTICE_REACH
    while head < len(queue):
        p = queue[head]
        head += 1
        i, j = index[p]
        ux, uy, vx, vy = local[p]
        near = rel[p]
        for di, dj, sx, sy in ((1, 0, ux, uy), (-1, 0, -ux, -uy), (0, 1, vx, vy), (0, -1, -vx, -vy)):
            best, best_d = -1, reach2 * (sx * sx + sy * sy)
            for rx, ry, q in near:
                dx, dy = rx - sx, ry - sy
                d = dx * dx + dy * dy
                if d < best_d:
                    best, best_d, ax, ay = q, d, rx, ry
            if best < 0:
                continue
            key = (i + di, j + dj)
            if key in at:
                if at[key] != best:
                    return None
                continue
            if best in index:
                return None
            index[best] = key
            at[key] = best
            local[best] = (ax * di, ay * di, vx, vy) if di else (ux, uy, ax * dj, ay * dj)
            queue.append(best)
    if len(at) < board.n_corners:
        return None
    ij = np.array(list(at.keys()))
    ij -= ij.min(axis=0)
    members = np.array(list(at.values()))
    shape = ij.max(axis=0) + 3  # one free index on each side for the ring test
    occ = np.zeros(shape, dtype=bool)
    occ[ij[:, 0] + 1, ij[:, 1] + 1] = True
    idx = np.full(shape, -1)
    idx[ij[:, 0] + 1, ij[:, 1] + 1] = members
    st = np.zeros(shape)
    st[ij[:, 0] + 1, ij[:, 1] + 1] = strength[members]
    if seen is not None:
        seen["pattern"] = _strong_extent(occ, st, board)
    best = None  # (min strength inside, i0, j0, ni, nj)
    for ni, nj in {(board.cols, board.rows), (board.rows, board.cols)}:
        for i0 in range(1, shape[0] - ni):
            for j0 in range(1, shape[1] - nj):
                if occ[i0:i0 + ni, j0:j0 + nj].all():
                    inside = float(st[i0:i0 + ni, j0:j0 + nj].min())
                    if best is None or inside > best[0]:
                        best = (inside, i0, j0, ni, nj)
    if best is None:
        return None
    inside, i0, j0, ni, nj = best
    win = idx[i0:i0 + ni, j0:j0 + nj]  # (ni, nj): first axis along u
    # the saddles one step outside the window (extrapolated from its two outer rows and columns, looked up
    # among all the frame's saddles, not only this cluster's) must be clearly weaker than the board's own:
    # the printed board's edge, where a single square's corner meets the white margin, is a weaker saddle;
    # equally strong ones mean a window of a bigger grid
    g = pts[win]
    outside = np.concatenate([2 * g[0] - g[1], 2 * g[-1] - g[-2], 2 * g[:, 0] - g[:, 1], 2 * g[:, -1] - g[:, -2]])
    step = np.concatenate([g[0] - g[1], g[-1] - g[-2], g[:, 0] - g[:, 1], g[:, -1] - g[:, -2]])
    frame = cand.frame_saddles
    _, all_strength, tree = frame if frame is not None else (pts, strength, cKDTree(pts))
    dist, near = tree.query(outside, distance_upper_bound=float(np.linalg.norm(step, axis=1).max()))
    hit = dist < LATTICE_REACH * np.linalg.norm(step, axis=1)
    ring = np.where(hit, all_strength[np.minimum(near, len(all_strength) - 1)], 0.0)
    if ring.max() * LATTICE_RING_RATIO > inside:
        return None
    strong = ring >= LATTICE_RING_STRONG * float(np.median(strength[win]))
    sides = np.split(strong, np.cumsum([g.shape[1], g.shape[1], g.shape[0]]))
    if max(float(side.mean()) for side in sides) >= LATTICE_RING_SIDE:
        return None
    grid = win.T if ni == board.cols else win  # rows x cols, a row-major order of the board
    fine = pts if cand.fine is None else np.asarray(cand.fine, dtype=np.float64)
    return fine[grid.reshape(-1)]


def _strong_extent(occ: np.ndarray, st: np.ndarray, board: Board) -> tuple[int, int] | None:
    """``(cols, rows)`` of the grid of strong saddles the walk found, in the declared board's orientation,
    when it is bigger than the declared board (the pattern continues past the declared corners); else None.

    A line of the walked grid (a row or a column of indices) belongs to the pattern when at least
    :data:`LATTICE_RING_SIDE` of its places hold a saddle at least :data:`LATTICE_RING_STRONG` times the median
    strength: the rule of the ring test, by which a board's printed edge (weaker saddles) does not count.
    """
    strong = occ & (st >= LATTICE_RING_STRONG * float(np.median(st[occ])))
    n = []
    for axis in (1, 0):
        count = strong.sum(axis=axis)
        n.append(int(np.sum(count >= LATTICE_RING_SIDE * max(int(count.max()), 1))))
    small, big = sorted(n)
    want_small, want_big = sorted((board.cols, board.rows))
    if small < want_small or big < want_big or (small, big) == (want_small, want_big):
        return None
    return (big, small) if board.cols >= board.rows else (small, big)
