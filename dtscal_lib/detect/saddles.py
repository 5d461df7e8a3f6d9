"""Steps 1-2: saddle points of the intensity and their grid-like clusters, the candidate regions."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..boards import DUCKIETOWN_BOARD, Board

#: candidate regions are grown to at least this many pixels on each side
MIN_REGION_SIDE = 48
#: pieces of a split board are merged if they come within this many saddle spacings of the seed
MERGE_REACH = 3.0


# --------------------------------------------------------------------------- step 1: saddles
def find_saddles(gray: np.ndarray, *, scale: float = 0.5, sigma: float = 1.0,
                 rel_threshold: float = 0.15, min_strength: float = 20.0):
    """Saddle points of the image intensity (checkerboard inner corners are saddles).

    The image is resized by ``scale``, blurred with a Gaussian of ``sigma`` (in the resized
    image's pixels) and the Hessian ``[[fxx, fxy], [fxy, fyy]]`` is taken with 3x3 Sobel
    filters. The saddle strength is ``-det H = fxy^2 - fxx fyy``; local maxima (5x5) above
    ``rel_threshold`` times the strongest saddle and above ``min_strength`` are kept.

    Parameters
    ----------
    gray : (h, w) uint8

    Returns
    -------
    points : (M, 2) float64 pixels of the full-size image
    angle : (M,) float64 radians, direction of the Hessian's first principal axis
        (turns by 90 degrees between neighbouring checkerboard corners)
    strength : (M,) float64 saddle strength
    """
    return _saddles(gray, scale, sigma, rel_threshold, min_strength)[:3]


#: the sub-pixel saddle (one Newton step to where the blurred intensity's gradient vanishes) is used only
#: when it lies within this many pixels of the resized image from the peak pixel; farther, the quadratic
#: model does not hold and the peak pixel is kept
SADDLE_NEWTON_REACH = 1.0


def _saddles(gray: np.ndarray, scale: float = 0.5, sigma: float = 1.0, rel_threshold: float = 0.15,
             min_strength: float = 20.0):
    """:func:`find_saddles`, and also each saddle at sub-pixel precision ``(M, 2)``.

    A checkerboard corner is a saddle of the blurred intensity: its gradient vanishes there (the pattern is
    point-symmetric about the corner). One Newton step from the peak pixel, ``-H^-1 grad f`` with the same
    Sobel filters, puts it there: about ten times closer to the refined corner than the peak pixel, so
    ``cornerSubPix`` needs one iteration fewer (benchmarks/README.md).
    The clusters and the lattice use the peak pixels (``points``).
    """
    small = gray if scale == 1 else cv2.resize(gray, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    f = cv2.GaussianBlur(small.astype(np.float32), (0, 0), sigma)
    fxx = cv2.Sobel(f, cv2.CV_32F, 2, 0, ksize=3)
    fyy = cv2.Sobel(f, cv2.CV_32F, 0, 2, ksize=3)
    fxy = cv2.Sobel(f, cv2.CV_32F, 1, 1, ksize=3)
    s = fxy * fxy - fxx * fyy
    peak = cv2.dilate(s, np.ones((5, 5), np.uint8))
    thr = max(rel_threshold * float(s.max()), float(min_strength))
    # local maxima above the threshold (the threshold first: few pixels pass it)
    above = np.flatnonzero(s.ravel() > thr)
    ys, xs = np.divmod(above[s.ravel()[above] >= peak.ravel()[above]], s.shape[1])
    a, b, c = fxx[ys, xs], fxy[ys, xs], fyy[ys, xs]
    angle = 0.5 * np.arctan2(2.0 * b, a - c).astype(np.float64)
    # pixel centres: small pixel k covers full-size pixels [k/scale, (k+1)/scale)
    pts = (np.column_stack([xs, ys]).astype(np.float64) + 0.5) / scale - 0.5
    # the Newton step: 3x3 Sobel first derivatives (8 f_x) at the peaks, with the Sobel second ones (4 f_xx)
    # (the image's edge pixel repeated beyond it)
    hs, ws = f.shape
    x0, x1 = np.maximum(xs - 1, 0), np.minimum(xs + 1, ws - 1)
    y0, y1 = np.maximum(ys - 1, 0), np.minimum(ys + 1, hs - 1)
    gx = (f[y0, x1] - f[y0, x0]) + 2 * (f[ys, x1] - f[ys, x0]) + (f[y1, x1] - f[y1, x0])
    gy = (f[y1, x0] - f[y0, x0]) + 2 * (f[y1, xs] - f[y0, xs]) + (f[y1, x1] - f[y0, x1])
    gx, gy = gx.astype(np.float64) / 8.0, gy.astype(np.float64) / 8.0
    a, b, c = a.astype(np.float64) / 4.0, b.astype(np.float64) / 4.0, c.astype(np.float64) / 4.0
    det = a * c - b * b  # < 0 at a saddle
    with np.errstate(divide="ignore", invalid="ignore"):
        step = -np.column_stack([c * gx - b * gy, a * gy - b * gx]) / det[:, None]
    keep = np.all(np.abs(step) <= SADDLE_NEWTON_REACH, axis=1)  # also False for NaN
    fine = pts + np.where(keep[:, None], step, 0.0) / scale
    return pts, angle, s[ys, xs].astype(np.float64), fine


# --------------------------------------------------------------------------- step 2: clusters
def board_regions(gray: np.ndarray, board: Board = DUCKIETOWN_BOARD, *, max_regions: int = 2,
                  min_fraction: float = 0.8) -> list[tuple[int, int, int, int]]:
    """Image regions that may hold ``board``: clusters of alternating saddle points.

    Parameters
    ----------
    gray : (h, w) uint8
    board : the board looked for (only its number of inner corners matters here)
    max_regions : at most this many clusters become candidates
    min_fraction : a cluster needs at least this fraction of ``board.n_corners`` saddles

    Returns
    -------
    list of ``(x0, y0, x1, y1)`` integer pixel boxes (x1, y1 exclusive) to try in order:
    for each of the (at most ``max_regions``) biggest clusters, the box around it and the
    pieces lying right next to it (if any), then its own box. Empty when nothing looks
    like a board.
    """
    return [c.box for c in _candidates(gray, board, max_regions=max_regions, min_fraction=min_fraction)]


@dataclass(frozen=True)
class _Candidate:
    """A region to try: its box, the saddles of its cluster(s) and their spacing (pixels)."""

    box: tuple[int, int, int, int]
    saddles: np.ndarray
    spacing: float
    strength: np.ndarray | None = None
    #: every saddle of the frame (points, strengths, their KD-tree): the lattice's ring test looks at all of them
    frame_saddles: tuple | None = None
    #: the saddles at sub-pixel precision (:func:`_saddles`), the lattice's corners (``saddles`` if None)
    fine: np.ndarray | None = None


def _candidates(gray: np.ndarray, board: Board, *, max_regions: int = 2,
                min_fraction: float = 0.8) -> list[_Candidate]:
    """:func:`board_regions` with each box's saddle cluster (see there)."""
    h, w = gray.shape[:2]
    pts, ang, strength, fine = _saddles(gray)
    n = len(pts)
    need = max(4, int(math.ceil(min_fraction * board.n_corners)))
    if n < need:
        return []
    k = min(5, n)  # itself and four grid neighbours
    tree = cKDTree(pts)
    dist, idx = tree.query(pts, k=k)
    frame = (pts, strength, tree)
    dist, idx = dist[:, 1:], idx[:, 1:]
    # neighbours in the grid: principal directions ~90 deg apart, at most twice as far as the
    # nearest saddle (a tilted board's rows and columns differ in spacing), similar strength
    # (same board, similar contrast)
    turn = np.abs(((ang[idx] - ang[:, None]) % np.pi) - np.pi / 2) < 0.4
    close = dist < 2.0 * np.maximum(dist[:, 1:2], 1e-9)
    similar = np.abs(np.log(strength[idx] / strength[:, None])) < math.log(6.0)
    ok = turn & close & similar
    # mutual links only: i links to j and j to i
    back = ((idx[idx] == np.arange(n)[:, None, None]) & ok[idx]).any(axis=2)
    mutual = ok & back
    adj = csr_matrix((np.ones(int(mutual.sum())), idx[mutual], np.concatenate([[0], np.cumsum(mutual.sum(1))])),
                     shape=(n, n))
    _, label = connected_components(adj, directed=True, connection="weak")  # the links are symmetric
    sizes = np.bincount(label)
    regions: list[_Candidate] = []
    for seed in np.argsort(-sizes)[:max_regions]:
        if sizes[seed] < need:
            break
        members = label == seed
        spacing = float(np.median(dist[members, 0]))
        # the cluster already includes the board's outer row of squares; add room for its
        # white margin and for corners the saddle test missed
        pad = 1.5 * spacing + 4.0
        regions.append(_Candidate(_box_around(pts[members], pad, w, h), pts[members], spacing,
                                  strength[members], frame, fine[members]))
        # a strongly foreshortened board (e.g. lying on the floor) can split into pieces where
        # its row and column spacings differ more than the link rule allows: first try the
        # box that also holds the pieces of at least 4 saddles within MERGE_REACH spacings
        other = np.flatnonzero((sizes[label] >= 4) & (label != seed))
        if len(other) * sizes[seed] <= 20000:  # few: all distances (as cKDTree's bound, strictly closer)
            d2 = ((pts[other, None, :] - pts[None, members, :]) ** 2).sum(-1)
            other = other[np.sqrt(d2.min(axis=1, initial=np.inf)) < MERGE_REACH * spacing]
        else:
            near, _ = cKDTree(pts[members]).query(pts[other], distance_upper_bound=MERGE_REACH * spacing)
            other = other[np.isfinite(near)]
        group = np.unique(label[other])
        if len(group):
            together = np.isin(label, np.append(group, seed))
            merged = _box_around(pts[together], pad, w, h)
            if merged != regions[-1].box:
                regions.insert(len(regions) - 1, _Candidate(merged, pts[together], spacing, strength[together],
                                                            frame, fine[together]))
    return regions


def _box_around(p: np.ndarray, pad: float, w: int, h: int) -> tuple[int, int, int, int]:
    x0, y0 = p.min(axis=0) - pad
    x1, y1 = p.max(axis=0) + pad
    return _grow_box(x0, y0, x1, y1, w, h)


def _grow_box(x0, y0, x1, y1, w, h, min_side: int = MIN_REGION_SIDE) -> tuple[int, int, int, int]:
    """Integer box inside the image, at least ``min_side`` on each side where the image allows."""
    box = []
    for lo, hi, size in ((x0, x1, w), (y0, y1, h)):
        lo, hi = int(math.floor(lo)), int(math.ceil(hi)) + 1
        short = min_side - (hi - lo)
        if short > 0:
            lo, hi = lo - short // 2 - 1, hi + short // 2 + 1
        box.append((max(0, lo), min(size, hi)))
    (bx0, bx1), (by0, by1) = box
    return bx0, by0, bx1, by1
