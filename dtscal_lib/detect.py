"""Checkerboard corner detection that stays fast when no board is in view.

ROS's ``camera_calibration`` runs OpenCV's classic ``findChessboardCorners`` (flags
``ADAPTIVE_THRESH | NORMALIZE_IMAGE | FAST_CHECK``) on every full frame. On a frame that
holds a board it answers in a few milliseconds, but on a cluttered frame with many
dark quadrilaterals (shelves, boxes, tiled floors, textured noise) its fast check lets
the frame through and it then tries about fifty thresholds and dilations before giving
up: 100-250 ms per 640x480 frame, several times the camera's frame period.

:func:`detect_board` puts a cheap, board-specific test in front of the same detector:

1. **Saddle points** (:func:`find_saddles`). On a half-size, slightly blurred image the
   Hessian of the intensity is computed with Sobel filters; inner corners of a
   checkerboard are saddles (``fxy^2 - fxx*fyy`` large) and, going from one corner to its
   neighbour along a row or column, the saddle's principal direction turns by 90 degrees
   (the dark diagonal becomes the light one).
2. **Grid clusters** (:func:`board_regions`). Saddles are linked to nearby saddles of
   similar strength whose principal direction differs by about 90 degrees, at most twice as
   far as the second-nearest saddle (mutual links only; the second-nearest, not the nearest:
   a board whose outer squares are cut narrow has saddles on its physical edge less than half
   a square from its outer corners); a connected cluster with at least 80 % as many saddles as the board has
   inner corners is a board candidate (its box is tried together with sizeable clusters
   right next to it, as a board seen edge-on can split into pieces, then alone). Clutter
   rarely produces such clusters: blocky texture gives many saddles, but with random
   polarity, so its clusters stay small.
3. **The grid straight from the saddles** (:func:`_saddle_lattice`): the cluster's saddles are walked as a
   grid (each corner's local grid vectors predict its neighbours); where they form exactly the board's
   ``rows x cols`` window, with only weaker saddles one step outside it (the printed edge, not more board),
   those are the raw corners and OpenCV's classic detector is not run at all (measured: 24 of 26 real
   photographs, 340 of the 353 detections of the recorded session; see ``benchmarks/bench_detect.py``).
   Otherwise, or where the refinement's checks reject that start:
   **classic detection on the candidate region only**: ``findChessboardCorners`` on the
   cluster's bounding box plus a margin (ROS's flags without ``FAST_CHECK``, whose quick
   test rejects many tightly cropped boards; small regions are tried again at twice the
   size). The live detector bounds this step's work (the classic detector answers in 1-5 ms
   where it finds a board, but spends 10-35 ms per region where it does not, typically on a
   board cut by the image edge, which the border rule rejects anyway): a region nearly the
   same as one already tried is skipped, a cluster of large squares (saddle spacing >= 20 px)
   is searched at full size only if a search at half size finds the board, and a small
   region touching the image edge gets no 2x retry.
   :func:`detect_board_still` then makes every skipped attempt where the live path found nothing.
4. **Sub-pixel refinement that stays inside each corner's own squares**
   (:func:`refine_corners_checked`). ROS refines every corner with one ``cornerSubPix``
   window of half the smallest corner spacing; on real boards (outer squares cut narrow,
   a printed outline, the board's edge or clutter close by) that window reaches past the
   corner's four squares and the outer corners converge on the edge, pixels away. Here each
   corner gets its own window (:func:`corner_windows`), the outer ring is restarted from the
   inner corners' local homography where it disagrees, each corner is checked against the
   quadratic through its 8 grid neighbours (:func:`grid_jump`, which a smoothly curled print
   passes; re-refined with half the window, or the board is found but rejected as
   ``"inconsistent_grid"``, naming the corner), and a corner off a smooth (cubic)
   grid through the others goes back to the detector's position or is dropped with the view.
   Last, every corner is polished once more on the image smoothed by a 1 px Gaussian
   (:func:`polish_corners`), which removes ``cornerSubPix``'s few-hundredths-of-a-pixel bias on
   sharp edges.

A frame without any candidate costs only steps 1-2 (about 1.5-3 ms at 640x480); see
``benchmarks/bench_detect.py`` for the measured figures and ratios against the ROS call,
which :func:`detect_board_ros` reproduces as the baseline.

Corner order follows ROS: OpenCV's row-major order (``cols`` corners per row), made to
run top to bottom (if the first corner is below the last, the order is reversed). This
module also fixes the handedness first (each row is reversed if the grid would appear
mirrored), so the same physical corner keeps its index while the board turns smoothly.

ROS rules kept: a detection with any corner within ``border_margin`` (8) pixels of the
image edge is rejected (reason ``"at_border"``).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from .boards import DUCKIETOWN_BOARD, Board
from .duckietown import BORDER_MARGIN_PX
from .errors import DtscalError, FrameError, Reason

#: OpenCV flags of ROS's calibrator (``FAST_CHECK`` is what the live calibrator adds)
ROS_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
#: cornerSubPix stopping rule used by ROS: 30 iterations or a step below 0.1 px
SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.1)
#: flags inside a candidate region: no FAST_CHECK (the saddle clusters already did that job,
#: and OpenCV's quick check rejects many tightly cropped boards)
REGION_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
#: candidate regions are grown to at least this many pixels on each side
MIN_REGION_SIDE = 48
#: a region whose longer side is at most this is tried again at twice the size if the
#: classic detector fails on it (small, far boards: its quads are too small at 1x)
UPSCALE_REGION_SIDE = 240

#: in the live detector, a candidate whose saddles are at least this far apart (pixels) is
#: searched on its region downsampled by 2 (squares of 10 px or more are found there)
HALF_SIZE_SPACING = 20.0

#: pieces of a split board are merged if they come within this many saddle spacings of the seed
MERGE_REACH = 3.0

REASON_NO_BOARD = Reason.NO_BOARD
REASON_AT_BORDER = Reason.AT_BORDER
#: a detection whose corners do not all lie on a smooth grid (cubic in the corner indices) is
#: dropped when a corner is off by more than this fraction of the smallest corner spacing
SMOOTH_GRID_TOLERANCE = 0.2


@dataclass(frozen=True)
class Detection:
    """The result of looking for a board in one frame.

    Attributes
    ----------
    found : bool
        True when the whole board was detected and no corner is near the image border.
    corners : (N, 2) float64 sub-pixel pixels or None
        Inner corners in the board's row-major order (``board.cols`` per row), rows
        running top to bottom. Also set when ``reason == "at_border"`` (so a UI can
        show the rejected board); ``None`` when no board was found.
    reason : str or None
        ``None`` when found, else ``"no_board"``, ``"at_border"`` or ``"inconsistent_grid"``
        (a board was found but some corner disagrees with its neighbours' grid even after
        re-refinement: rejected as unreliable rather than fed to a calibration; ``corners``
        holds the rejected board and ``detail`` names the corner and its distance).
    board : Board
    image_size : (w, h)
    detail : str or None
        For a found-and-rejected board (``"inconsistent_grid"``): which corner (row and column
        of the board's inner-corner grid, from 1) is how far off its neighbours' grid, against
        which tolerance.
    """

    found: bool
    corners: np.ndarray | None
    reason: str | None
    board: Board = field(default=DUCKIETOWN_BOARD)
    image_size: tuple[int, int] = (0, 0)
    detail: str | None = None

    def __bool__(self) -> bool:
        return self.found


# --------------------------------------------------------------------------- input
def to_gray(image) -> np.ndarray:
    """Any camera frame as a contiguous 8-bit gray image.

    Parameters
    ----------
    image : (h, w), (h, w, 1), (h, w, 3) BGR or (h, w, 4) BGRA array
        ``uint8``; ``uint16`` (scaled by 1/257); ``bool``; or float (values in [0, 1]
        are scaled by 255, larger values are taken as 0-255 and clipped).

    Returns
    -------
    (h, w) uint8

    Raises
    ------
    FrameError
        ``reason="empty"`` for ``None`` or an empty array, ``"bad_shape"`` for other shapes,
        ``"bad_dtype"`` for unsupported pixel types, ``"bad_values"`` for NaN/inf pixels.
    """
    if image is None:
        raise FrameError(Reason.EMPTY, "the frame is None; the source returned no image (check the camera/bag)")
    img = np.asarray(image)
    if img.size == 0:
        raise FrameError(Reason.EMPTY, f"the frame is empty (shape {img.shape}); skip it and read the next one")
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if not (img.ndim == 2 or (img.ndim == 3 and img.shape[2] in (3, 4))):
        raise FrameError(
            Reason.BAD_SHAPE,
            f"expected a gray (h, w), BGR (h, w, 3) or BGRA (h, w, 4) image, got shape {img.shape}; "
            "decode the frame to an image first",
        )
    img = _to_uint8(img)
    if img.ndim == 3:
        code = cv2.COLOR_BGR2GRAY if img.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
        img = cv2.cvtColor(np.ascontiguousarray(img), code)
    return np.ascontiguousarray(img)


def _to_uint8(img: np.ndarray) -> np.ndarray:
    if img.dtype == np.uint8:
        return img
    if img.dtype == np.bool_:
        return img.astype(np.uint8) * 255
    if img.dtype == np.uint16:
        return ((img.astype(np.uint32) + 128) // 257).astype(np.uint8)
    if np.issubdtype(img.dtype, np.floating):
        if not np.all(np.isfinite(img)):
            raise FrameError(Reason.BAD_VALUES, "the frame contains NaN or infinite pixels; it cannot be used")
        scale = 255.0 if float(img.max()) <= 1.0 else 1.0
        return np.clip(np.rint(img * scale), 0, 255).astype(np.uint8)
    raise FrameError(
        Reason.BAD_DTYPE,
        f"unsupported pixel type {img.dtype}; give uint8, uint16 or float images (e.g. img.astype(np.uint8))",
    )


def _as_bgr(image) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim == 2:
        return cv2.cvtColor(_to_uint8(img), cv2.COLOR_GRAY2BGR)
    if img.ndim == 3 and img.shape[2] == 4:
        return cv2.cvtColor(_to_uint8(img), cv2.COLOR_BGRA2BGR)
    if img.ndim == 3 and img.shape[2] == 3:
        return _to_uint8(img).copy()
    raise FrameError(Reason.BAD_SHAPE, f"cannot draw on an image of shape {img.shape}")


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
    Sobel filters, puts it there. Measured on the 26 real photographs (``data/real``, the 1300 corners the
    kit finds): 0.08 px median, 0.19 px 90th percentile, 0.43 px at most from the refined corners, against
    0.78 / 1.12 / 1.50 px for the peak pixel; started there, ``cornerSubPix`` needs one iteration fewer
    (the refinement's first pass). The clusters and the lattice use the peak pixels (``points``).
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


#: a saddle is taken as the lattice's next corner when it lies within this fraction of the step from where
#: the previous corner's local grid vectors predict it (perspective changes a step by a few percent from one
#: corner to the next; the edge saddles of narrow outer squares lie about half a step off: see _saddle_lattice)
LATTICE_REACH = 0.3
#: the ring test of :func:`_saddle_lattice`, on the saddles one grid step outside the window (all the frame's
#: saddles, not only the cluster's). A window of a bigger grid has true corners there; a board has the weaker
#: saddles of its printed edge (a single square's corner against the white margin) or none. The window is refused
#: when the board's weakest corner is below LATTICE_RING_RATIO times the ring's strongest saddle, or when on one
#: side of the ring at least LATTICE_RING_SIDE of the positions hold a saddle at least LATTICE_RING_STRONG times
#: the board's median corner strength. Measured on every candidate window (tests/test_detect_lattice.py):
#:   wrong board sizes (data/real searched as 7x5, 8x6, 9x5, 8x5, 7x6, 6x4, 5x5: 331 windows; the recording as
#:   6x4, 5x5, 6x5, 7x4, 5x4: 452): strongest side 0.78-1.0 and 0.2-1.0 (3 below 0.6), weakest/ring 0.38-1.06;
#:   accepted with both rules: 0 of 783;
#:   the right board: data/real 42 of 45 windows accepted, the stress set 72 of 75, the recording 362 of 363
#:   (strongest side of a right board: median 0, at most 0.44 on data/real and 0.43 on the recording).
#: A refused window goes to the classic detector (slower; the refined corners then start from its corners).
LATTICE_RING_RATIO = 0.8
LATTICE_RING_SIDE = 0.6
LATTICE_RING_STRONG = 0.5


def _saddle_lattice(cand: _Candidate, board: Board) -> np.ndarray | None:
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

    Measured: the lattice gives the board in 24 of 26 views of ``data/real`` and 339 of the 353 detections of
    the recorded session, saving the classic detector's 3-10 ms per view; the refined corners agree with
    those from the classic start to 0.0001 px median (0.14 px worst, where the polish step's 0.1 px rule
    decides differently); the stress set's accuracy is unchanged and the recording's worst frame improved
    (1.58 -> 0.67 px from the truth; ``benchmarks/bench_detect.py``).
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


# --------------------------------------------------------------------------- corners
def order_corners(corners: np.ndarray, board: Board = DUCKIETOWN_BOARD) -> np.ndarray:
    """Put detected corners in a consistent order: right-handed grid, rows running top to bottom.

    1. Handedness: if the grid appears mirrored (row step x column step < 0 in image
       coordinates, x right and y down), each row is reversed.
    2. ROS's rule: for a non-square board, if the first corner is below the last, the
       whole order is reversed. For a square board ROS rotates the grid until the last
       corner is right of and below the first; so does this function.

    Parameters
    ----------
    corners : (N, 2) pixels in some row-major order of the board

    Returns
    -------
    (N, 2) float64 pixels, a reordered copy
    """
    c = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    if len(c) != board.n_corners:
        raise DtscalError(f"expected {board.n_corners} corners for a {board.describe()} board, got {len(c)}")
    grid = c.reshape(board.rows, board.cols, 2)
    row_step = grid[0, -1] - grid[0, 0]
    col_step = grid[-1, 0] - grid[0, 0]
    if row_step[0] * col_step[1] - row_step[1] * col_step[0] < 0:
        grid = grid[:, ::-1]
    if board.rows != board.cols:
        if grid[0, 0, 1] > grid[-1, -1, 1]:
            grid = grid[::-1, ::-1]
    else:
        # square board: four right-handed orders; choose the one whose diagonal points down-right
        for _ in range(4):
            d = grid[-1, -1] - grid[0, 0]
            if d[0] >= 0 and d[1] >= 0:
                break
            grid = np.rot90(grid)  # a 90-degree turn of the index grid keeps the handedness
        else:
            # no order points down-right (board seen nearly edge-on): use the top-to-bottom rule
            if grid[0, 0, 1] > grid[-1, -1, 1]:
                grid = grid[::-1, ::-1]
    return np.ascontiguousarray(grid.reshape(-1, 2))


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
#: finished with :data:`REFINE_CRITERIA`. ``cornerSubPix`` contracts a start error by about 20x per
#: iteration (measured on ``data/real``: steps of 0.74, 0.04, 0.003 px median from the saddle pixels), so a
#: step below 0.1 px leaves about 0.005 px; from the sub-pixel saddles (:func:`_saddles`) most corners stop
#: after one or two iterations instead of two or three (first pass 1.40 -> 0.96 ms median on ``data/real``)
FIRST_PASS_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.1)
#: the kit's last refinement step works on the image smoothed by a Gaussian of this sigma, pixels
#: (see :func:`polish_corners`)
REFINE_SIGMA = 1.0
#: a corner that the smoothed step would move this far (pixels) or more keeps its unsmoothed position
POLISH_MAX_MOVE_PX = 0.1
#: a corner farther than this from the smooth (quadratic) grid through its 8 neighbours
#: (:func:`grid_jump`; in pixels, or this fraction of its local square size, whichever is larger;
#: x 1.51 at the board's four corners, where the check extrapolates: :func:`grid_tolerance`) jumped
#: off the grid. Measured by ``benchmarks/grid_tolerance.py`` on the 26 real photographs of
#: ``data/real/``: flat, the 728 inner corners jump by median 0.12 px, 99th percentile 0.36 px, at most
#: 0.49 px (0.017 of a square), i.e. a corner noise of about 0.07 px per coordinate (the jump's noise
#: gain is 1.5), the outer ring at most 0.19 of its tolerance. Curled smoothly (``cv2.remap``; copies
#: at 0.6x, squares of 12-23 px as Duckietown's 17 mm squares on the floor, the print curling up by
#: 6 or 12 px at its sides; or full size, waves of 5 px amplitude and 300 px wavelength): inner jumps
#: at most 0.75 px (0.033 of a square), the outer ring at most 0.87 of its tolerance. Refused: 1 of the
#: 26 views curled by 12 px (a detection with a corner 21 px off) and 2 of the 52 waved ones (by the
#: smooth-grid guard, :data:`SMOOTH_GRID_TOLERANCE`, a global cubic that a wave of one period per
#: board exceeds). 1 px is twice the largest flat jump; 0.1 of a square stays above the curled ones
#: while a corner displaced by a sixth of a square is caught and named (``tests/test_detect_curled.py``).
#: The former check, a homography through the 8 neighbours with max(0.75 px, 0.1 square), cannot
#: follow a bend: it refused 5 of the 26 views curled by 12 px, 5 of the 52 waved ones, and
#: Duckietown's curled DD24 print (1.74 px against 1.59 px).
GRID_TOLERANCE_PX = 1.0
GRID_TOLERANCE_FRACTION = 0.1
REASON_INCONSISTENT = Reason.INCONSISTENT_GRID


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
    radius = corner_windows(c, board, margin=WINDOW_MARGIN_PX + sigma)
    # cornerSubPix reads 1 px beyond its window, bilinearly: the smoothing must be exact that far
    img = refine_image(gray, c, float(radius.max(initial=0)) + 3.0, sigma)
    p = _subpix(img, c, radius)
    use = np.linalg.norm(p - c, axis=1) < POLISH_MAX_MOVE_PX
    if skip is not None:
        use &= ~np.asarray(skip, dtype=bool)
    c[use] = p[use]
    return c, use


def _patches(img: np.ndarray, pts: np.ndarray, n: int) -> np.ndarray:
    """``(M, n, n)`` float32: ``cv2.getRectSubPix(img, (n, n), pt)`` of every point at once (``img`` float32).

    The same bilinear sampling (pixel ``(i, j)`` of a patch is the image at ``pt + (j, i) - (n - 1) / 2``),
    gathered for all points in one numpy step instead of one OpenCV call per point (measured on the real
    photographs: 26 outer corners in about 0.1 ms instead of 0.5 ms). Points whose patch reaches past the
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
                   threshold: float = 0.2) -> np.ndarray:
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


def _near_border(corners: np.ndarray, size: tuple[int, int], margin: float) -> bool:
    w, h = size
    x, y = corners[:, 0], corners[:, 1]
    inside = (x > margin) & (x < w - margin) & (y > margin) & (y < h - margin)
    return not bool(np.all(inside))


def _finish(gray: np.ndarray, raw: np.ndarray, board: Board, border_margin: float,
            ros: bool = False) -> Detection:
    """Order, refine and check a raw detection. ``ros=True`` refines as ROS does (one window,
    :func:`subpix_radius`, no checks): the baseline."""
    h, w = gray.shape
    raw = order_corners(raw, board)
    if ros:
        corners = refine_corners(gray, raw, board)
    else:
        corners, ok = refine_corners_checked(gray, raw, board)
        if not ok:
            # a board running off the image is reported as such (ROS's rule), not as inconsistent
            # ... and so is a board whose corners off the grid have squares the image edge cuts (within a
            # square of it): the edge pulled their refinement, the grid check is its echo
            reach = (border_margin + _local_square(raw, board))[:, None]
            cut = np.any((raw < reach) | (raw > np.array([w - 1.0, h - 1.0]) - reach), axis=1)
            off = ((grid_jump(corners, board) > grid_tolerance(raw, board))
                   | (grid_residuals(corners, board, SMOOTH_GRID_TOLERANCE) > SMOOTH_GRID_TOLERANCE))
            if (_near_border(raw, (w, h), border_margin) or _near_border(corners, (w, h), border_margin)
                    or np.any(cut & off)):
                return Detection(False, raw, REASON_AT_BORDER, board, (w, h))
            return Detection(False, corners, REASON_INCONSISTENT, board, (w, h), grid_rejection(corners, board))
    if _near_border(corners, (w, h), border_margin):
        return Detection(False, corners, REASON_AT_BORDER, board, (w, h))
    return Detection(True, corners, None, board, (w, h))


def _check_inputs(board: Board, border_margin: float) -> None:
    if not isinstance(board, Board):
        raise DtscalError(f"board must be a dtscal_lib.boards.Board, got {type(board).__name__}; "
                          "e.g. parse_board('7x5', 0.031)")
    if not (np.isfinite(border_margin) and border_margin >= 0):
        raise DtscalError(f"border_margin must be a non-negative number of pixels, got {border_margin!r}")


# --------------------------------------------------------------------------- public detectors
def detect_board(image, board: Board = DUCKIETOWN_BOARD, *,
                 border_margin: float = BORDER_MARGIN_PX) -> Detection:
    """Find the board's inner corners, quickly even when there is no board.

    Saddle-point clusters (:func:`board_regions`) select at most two candidate regions;
    OpenCV's classic detector with ROS's flags runs only there; corners are ordered
    (:func:`order_corners`) and refined (:func:`refine_corners_checked`) on the full image.

    Parameters
    ----------
    image : gray, BGR or BGRA frame (see :func:`to_gray`)
    board : the board to look for (inner corners)
    border_margin : reject detections with a corner within this many pixels of the edge

    Returns
    -------
    Detection

    Examples
    --------
    >>> import numpy as np
    >>> detect_board(np.zeros((480, 640), np.uint8)).reason
    'no_board'
    """
    _check_inputs(board, border_margin)
    gray = to_gray(image)
    return _detect_in_regions(gray, board, border_margin, live=True)


def _classic(roi: np.ndarray, board: Board, scale: float):
    """The classic detector on ``roi`` resized by ``scale``; corners in ``roi``'s pixels or None."""
    img = roi if scale == 1 else cv2.resize(
        roi, None, fx=scale, fy=scale, interpolation=cv2.INTER_LINEAR if scale > 1 else cv2.INTER_AREA)
    ok, raw = cv2.findChessboardCorners(img, board.pattern_size, flags=REGION_FLAGS)
    if not ok:
        return None
    # pixel centres: resized pixel k sits at (k + 0.5) / scale - 0.5 in the region
    return (raw.reshape(-1, 2).astype(np.float64) + 0.5) / scale - 0.5


def _same_box(a, b, tol: float) -> bool:
    return all(abs(p - q) <= tol for p, q in zip(a, b))


def _detect_in_regions(gray: np.ndarray, board: Board, border_margin: float, live: bool) -> Detection:
    """Classic detection in the saddle clusters' regions (see :func:`detect_board`).

    ``live=False`` is the original, thorough order: every region at full size, small ones again
    at twice the size. ``live=True`` bounds the work per frame (the classic detector answers
    in 1-5 ms where it finds a board but spends 10-35 ms per region where it does not, mostly
    on boards cut by the image edge, which the border rule would reject anyway):

    - a region whose box differs from an already tried one by at most a square on each side
      is skipped (a split board's merged box and the seed's own box are often nearly the same);
    - a cluster of large squares (saddle spacing at least :data:`HALF_SIZE_SPACING`) is first
      searched on the region downsampled by 2 (squares of 10 px or more are still found there, at
      a quarter of the cost); only if the board is found there is the full-size search made, whose
      corners are used (so they are those of the thorough order);
    - the 2x retry of small regions is not made for a region that touches the image edge (a
      small board there is nearly always cut by the edge).
    """
    h, w = gray.shape
    tried: list[tuple[int, int, int, int]] = []
    for cand in _candidates(gray, board):
        x0, y0, x1, y1 = cand.box
        roi = gray[y0:y1, x0:x1]
        if min(roi.shape) < 16:  # OpenCV's adaptive threshold needs a few pixels
            continue
        if live and any(_same_box(cand.box, t, cand.spacing) for t in tried):
            continue
        tried.append(cand.box)
        if live:
            # the board straight from the saddles where they form exactly its grid; the classic
            # detector only where they do not, or where the refinement's checks reject the result
            lattice = _saddle_lattice(cand, board)
            if lattice is not None:
                det = _finish(gray, lattice, board, border_margin)
                if det.found or det.reason == REASON_AT_BORDER:
                    return det
        if live and cand.spacing >= HALF_SIZE_SPACING:
            # a quick test at half size; the corners then come from the full-size search as in
            # the thorough order (the same start, so the same refined corners), or from the
            # half-size one if the full-size search fails
            half = _classic(roi, board, 0.5)
            if half is None:
                continue
            raw = _classic(roi, board, 1.0)
            raw = half if raw is None else raw
            return _finish(gray, raw + (x0, y0), board, border_margin)
        else:
            scales = [1.0]
            at_edge = x0 == 0 or y0 == 0 or x1 == w or y1 == h
            if max(roi.shape) <= UPSCALE_REGION_SIDE and not (live and at_edge):
                scales.append(2.0)
        for scale in scales:
            raw = _classic(roi, board, scale)
            if raw is not None:
                return _finish(gray, raw + (x0, y0), board, border_margin)
    return Detection(False, None, REASON_NO_BOARD, board, (w, h))


def detect_board_ros(image, board: Board = DUCKIETOWN_BOARD, *,
                     border_margin: float = BORDER_MARGIN_PX) -> Detection:
    """The ROS ``camera_calibration`` baseline: the classic detector on the full frame.

    ``findChessboardCorners(ADAPTIVE_THRESH | NORMALIZE_IMAGE | FAST_CHECK)`` on the whole
    image, then the same ordering and border rule as :func:`detect_board` and ROS's refinement
    (one ``cornerSubPix`` window of :func:`subpix_radius` for all corners, no checks).
    Kept as the reference for benchmarks and tests; can take hundreds of milliseconds on a
    cluttered frame without a board.
    """
    _check_inputs(board, border_margin)
    gray = to_gray(image)
    h, w = gray.shape
    ok, raw = cv2.findChessboardCorners(gray, board.pattern_size, flags=ROS_FLAGS)
    if not ok:
        return Detection(False, None, REASON_NO_BOARD, board, (w, h))
    return _finish(gray, raw.reshape(-1, 2).astype(np.float64), board, border_margin, ros=True)


def detect_board_still(image, board: Board = DUCKIETOWN_BOARD, *,
                       border_margin: float = BORDER_MARGIN_PX) -> Detection:
    """Thorough detection for a single still frame, where time does not matter.

    :func:`detect_board` first (so both refine identically where it finds the board); when it
    finds nothing, the candidate regions again with every attempt the live path skips to bound
    its time (full size, 2x retries), then OpenCV's classic detector on the
    whole frame with ``ADAPTIVE_THRESH | NORMALIZE_IMAGE`` and no ``FAST_CHECK``, as
    Duckietown's extrinsic calibration runs it. On a rectified floor view the far squares
    are only about 12 px tall; ``FAST_CHECK`` and the region search can miss such a board
    that the full search finds. Too slow for a live stream on a board-free frame (up to a
    few hundred ms); meant for the extrinsic capture and for notebooks.
    """
    det = detect_board(image, board, border_margin=border_margin)
    if det.found or det.reason == REASON_AT_BORDER:
        return det
    gray = to_gray(image)
    thorough = _detect_in_regions(gray, board, border_margin, live=False)
    if thorough.found or thorough.reason == REASON_AT_BORDER:
        return thorough
    ok, raw = cv2.findChessboardCorners(gray, board.pattern_size, flags=REGION_FLAGS)
    if not ok:
        return det
    return _finish(gray, raw.reshape(-1, 2).astype(np.float64), board, border_margin)


# --------------------------------------------------------------------------- drawing
def draw_detection(image, detection: Detection) -> np.ndarray:
    """A BGR copy of ``image`` with the detection drawn like ``cv2.drawChessboardCorners``.

    A found board gets coloured corners joined row by row; a board rejected at the border
    gets red circles; nothing is drawn when no board was found.

    Parameters
    ----------
    image : gray, BGR or BGRA frame
    detection : Detection for this image

    Returns
    -------
    (h, w, 3) uint8 BGR
    """
    out = _as_bgr(image)
    if detection.corners is not None:
        pts = np.asarray(detection.corners, dtype=np.float32).reshape(-1, 1, 2)
        cv2.drawChessboardCorners(out, detection.board.pattern_size, pts, bool(detection.found))
    return out
