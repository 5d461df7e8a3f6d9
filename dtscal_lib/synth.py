"""Synthetic recorded Duckiebot sessions with exact ground truth.

The kit ships a recording of a (simulated) Duckiebot camera so that every notebook,
test and demo runs without a robot. This module renders it:

* an **intrinsic session**: someone sweeps the printed calibration sheet by hand in
  front of a robot standing on a table; the board goes left, right, up, down, near,
  far and tilted, leaves the view and comes back, as the ROS calibrator asks;
* an **extrinsic capture**: the robot stands on a Duckietown mat with the sheet lying
  flat at the Duckietown placement in front of it.

How a frame is made (a physically sensible, if simple, camera)
--------------------------------------------------------------
1. *Inverse mapping.* Every pixel is split into ``s x s`` sub-pixels. Each sub-pixel
   centre is undistorted once per camera (:func:`camera.undistort_normalized`, Newton)
   into a viewing ray ``(x, y, 1)``. A plane ``X = R [p0, p1, 0] + t`` maps rays to plane
   coordinates by the homography ``[p0, p1, 1] ~ [r1 r2 t]^-1 (x, y, 1)``; rays that hit
   the plane behind the camera are discarded.
2. *Analytic texture.* The checkerboard, the paper and the floor are functions of the
   plane coordinates, evaluated exactly at every sub-pixel (no texture interpolation),
   then area-averaged to pixels (``cv2.INTER_AREA``): box-filter anti-aliasing.
3. *Camera effects.* Board over a static background (premultiplied alpha), linear motion
   blur along the board's image motion during the exposure (symmetric kernel, so the
   blurred image is centred on the mid-exposure pose the truth describes), lens blur,
   vignetting, exposure changes, signal-dependent sensor noise, 8-bit quantisation, and
   finally JPEG compression as the camera node publishes it.

The truth of every inner corner is :func:`camera.project_points` of the board's object
points with the same camera; the rendering never uses those projections, so the two are
independent and the tests compare them.

Everything is deterministic: one seed, per-frame random streams
``np.random.default_rng([seed, stream, index])`` (so one frame can be re-rendered on its
own), fixed bag time stamps, no wall-clock time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable

import cv2
import numpy as np

from . import duckietown as dt
from .boards import DUCKIETOWN_BOARD, Board, CharucoBoard, ground_points
from .camera import CameraModel, as_rotation, pixel_to_normalized, project_points, undistort_normalized
from . import safe_write
from .errors import DtscalError

#: the seed the shipped ``data/`` was generated with
DEFAULT_SEED: int = 20240611
#: the synthetic robot's name
SYNTH_ROBOT: str = "synthbot"
#: JPEG quality of the simulated camera node
JPEG_QUALITY: int = 85
#: sub-pixels per pixel side used for anti-aliasing
SUPERSAMPLE: int = 3
#: bag time of the first intrinsic frame (fixed: regenerating gives identical files)
STAMP0_NS: int = 1_700_000_000 * 10**9
#: the extrinsic capture starts this long after the first intrinsic frame
EXTRINSIC_OFFSET_NS: int = 120 * 10**9
#: random streams
_STREAM_INTRINSIC, _STREAM_EXTRINSIC, _STREAM_SCENE = 1, 2, 3


# =========================================================================== data types
@dataclass(frozen=True)
class Sheet:
    """The printed sheet carrying the checkerboard (A3 landscape by default).

    The pattern's squares are centred on the paper. Sizes in metres, ``width`` along the
    board's x axis (its rows of corners), ``height`` along its y axis.
    """

    width: float = 0.420
    height: float = 0.297
    #: reflectances: paper and ink (fractions of a perfect white)
    paper: float = 0.86
    ink: float = 0.05


A3_SHEET = Sheet()


@dataclass(frozen=True, eq=False)
class SynthFrame:
    """One frame of a synthetic recording.

    Attributes
    ----------
    index : position in its bag (0-based)
    stamp_ns : header stamp and bag time, integer nanoseconds
    image : (480, 640, 3) uint8 BGR, the decoded JPEG (exactly what a reader of the bag sees)
    jpeg : the compressed bytes written to the bag
    rvec, tvec : (3,) board -> camera pose, or None when no board is in the scene
    corners : (35, 2) float64 true inner-corner pixels (OpenCV row-major order), or None
        when the board is not in the picture at all
    visible : True when the whole checker pattern is inside the image and every inner
        corner is at least ``duckietown.BORDER_MARGIN_PX`` from the border
    blur_px : length of the motion-blur streak (pixels), 0 when none
    """

    index: int
    stamp_ns: int
    image: np.ndarray
    jpeg: bytes
    rvec: np.ndarray | None
    tvec: np.ndarray | None
    corners: np.ndarray | None
    visible: bool
    blur_px: float = 0.0


@dataclass(frozen=True, eq=False)
class Renderer:
    """A camera prepared for rendering: one undistorted ray per sub-pixel. The kit's one ray caster.

    Build it once with :func:`make_renderer` (a few seconds) and reuse it for every
    frame of that camera. :meth:`plane_coords` casts the rays onto a plane (a board, the
    floor) and :meth:`downsample` area-averages what a texture made of them to pixels: the
    recorded session, the stress set, the course's board images and the benchmarks' frames
    are all drawn this way.
    """

    camera: CameraModel
    supersample: int
    #: (H*s, W*s, 2) float64 normalized undistorted coordinates of the sub-pixel centres
    rays: np.ndarray = field(repr=False)

    def plane_coords(self, R, t, window: tuple[int, int, int, int] | None = None):
        """Where each sub-pixel's ray meets the plane ``X = R [p0, p1, 0] + t``: ``(p0, p1, hit)``.

        ``window`` ``(x0, y0, x1, y1)`` (pixels) limits the rays to that part of the image.
        Arrays of shape ``(rows * s, cols * s)``; ``hit`` is False where the ray meets the
        plane behind the camera (or not at all).
        """
        rays = self.rays
        if window is not None:
            x0, y0, x1, y1 = window
            s = self.supersample
            rays = rays[y0 * s : y1 * s, x0 * s : x1 * s]
        return _plane_coords(rays, as_rotation(R), np.asarray(t, dtype=np.float64).reshape(3))

    def downsample(self, a: np.ndarray) -> np.ndarray:
        """Sub-pixel values (``s`` x ``s`` per pixel) area-averaged to pixels (``cv2.INTER_AREA``)."""
        return _downsample(a, self.supersample)


def synthetic_camera() -> CameraModel:
    """The simulated Duckiebot camera: the SHIPPED default intrinsics, distortion and P."""
    return CameraModel(dt.default_K(), dt.default_dist(), dt.IMAGE_SIZE, "plumb_bob", dt.default_P())


def make_renderer(camera: CameraModel | None = None, supersample: int = SUPERSAMPLE) -> Renderer:
    """Undistort every sub-pixel centre of ``camera`` once.

    Sub-pixel ``k`` of pixel ``u`` (``s`` per side) has its centre at
    ``u + (k + 0.5) / s - 0.5``, so averaging ``s x s`` blocks is an exact box filter
    over each pixel.
    """
    camera = synthetic_camera() if camera is None else camera
    s = int(supersample)
    if s < 1 or s > 6:
        raise DtscalError(f"supersample must be 1..6 sub-pixels per side, got {supersample}")
    w, h = camera.size
    u = (np.arange(w * s) + 0.5) / s - 0.5
    v = (np.arange(h * s) + 0.5) / s - 0.5
    uu, vv = np.meshgrid(u, v)
    xy = undistort_normalized(pixel_to_normalized(np.column_stack([uu.ravel(), vv.ravel()]), camera.K),
                              camera.dist)
    return Renderer(camera, s, xy.reshape(h * s, w * s, 2))


# =========================================================================== geometry helpers
def _rot(axis: str, deg: float) -> np.ndarray:
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _rvec(R: np.ndarray) -> np.ndarray:
    return cv2.Rodrigues(np.asarray(R, dtype=np.float64))[0].reshape(3)


def _pattern_outline(board: Board, n: int = 24) -> np.ndarray:
    """Points along the outer edge of the squares, (4n, 3) board coordinates."""
    s = board.square
    x0, x1, y0, y1 = -s, board.cols * s, -s, board.rows * s
    t = np.linspace(0.0, 1.0, n, endpoint=False)
    edges = [np.column_stack([x0 + (x1 - x0) * t, np.full(n, y0)]),
             np.column_stack([np.full(n, x1), y0 + (y1 - y0) * t]),
             np.column_stack([x1 - (x1 - x0) * t, np.full(n, y1)]),
             np.column_stack([np.full(n, x0), y1 - (y1 - y0) * t])]
    pts = np.vstack(edges)
    return np.column_stack([pts, np.zeros(len(pts))])


def _sheet_outline(board: Board, sheet: Sheet, n: int = 24) -> np.ndarray:
    cx, cy = board.centre[:2]
    t = np.linspace(0.0, 1.0, n, endpoint=False)
    x0, x1 = cx - sheet.width / 2, cx + sheet.width / 2
    y0, y1 = cy - sheet.height / 2, cy + sheet.height / 2
    pts = np.vstack([np.column_stack([x0 + (x1 - x0) * t, np.full(n, y0)]),
                     np.column_stack([np.full(n, x1), y0 + (y1 - y0) * t]),
                     np.column_stack([x1 - (x1 - x0) * t, np.full(n, y1)]),
                     np.column_stack([np.full(n, x0), y1 - (y1 - y0) * t])])
    return np.column_stack([pts, np.zeros(len(pts))])


def true_corners(camera: CameraModel, board: Board, rvec, tvec) -> tuple[np.ndarray | None, bool]:
    """Ground-truth inner corners of a board pose and whether the whole board is visible.

    Returns
    -------
    corners : (N, 2) float64 pixels (``project_points`` of the object points), or None when
        some corner is behind the camera or no corner falls inside the image
    fully_visible : every inner corner at least ``BORDER_MARGIN_PX`` inside the image and
        the whole outline of the squares inside the image
    """
    R = as_rotation(rvec)
    t = np.asarray(tvec, dtype=np.float64).reshape(3)
    X = board.object_points()
    outline = _pattern_outline(board)
    if np.any((X @ R.T + t)[:, 2] <= 1e-3):
        return None, False
    uv = project_points(X, R, t, camera.K, camera.dist)
    w, h = camera.size
    inside = (uv[:, 0] >= -0.5) & (uv[:, 0] <= w - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] <= h - 0.5)
    if not inside.any():
        return None, False
    m = dt.BORDER_MARGIN_PX
    visible = bool(np.all((uv[:, 0] >= m) & (uv[:, 0] <= w - 1 - m) & (uv[:, 1] >= m) & (uv[:, 1] <= h - 1 - m)))
    if visible:
        if np.any((outline @ R.T + t)[:, 2] <= 1e-3):
            visible = False
        else:
            ov = project_points(outline, R, t, camera.K, camera.dist)
            visible = bool(np.all((ov[:, 0] >= 0) & (ov[:, 0] <= w - 1) & (ov[:, 1] >= 0) & (ov[:, 1] <= h - 1)))
    return uv, visible


def ground_truth_homography(camera: CameraModel, rvec, tvec, P=None) -> np.ndarray:
    """Exact ground homography: rectified pixel -> ground metres (robot frame).

    The camera sees the ground plane ``Z = 0`` of the robot frame with the pose
    ``Xc = R X + t``. A ground point ``(X, Y)`` lands on the rectified image (camera matrix
    ``P[:, :3]``, no rotation) at ``p ~ P3 [r1 r2 t] (X, Y, 1)``, so

        ``H = (P3 [r1 r2 t])^-1``, scaled so that ``H[2, 2] = 1``.

    Parameters
    ----------
    camera : the camera (its ``P`` is used when ``P`` is None)
    rvec, tvec : robot (ground) frame -> camera pose
    P : (3, 4) or (3, 3) rectified projection matrix, e.g. ``duckietown.default_P()``

    Returns
    -------
    (3, 3) float64 homography, rectified pixel -> ground metres, ``H[2, 2] = 1``
    """
    R = as_rotation(rvec)
    t = np.asarray(tvec, dtype=np.float64).reshape(3)
    P3 = np.asarray(camera.P if P is None else P, dtype=np.float64)[:3, :3]
    G = P3 @ np.column_stack([R[:, 0], R[:, 1], t])
    if abs(np.linalg.det(G)) < 1e-12:
        raise DtscalError("the camera sees the ground plane edge-on; no ground homography exists for this pose")
    H = np.linalg.inv(G)
    if abs(H[2, 2]) < 1e-12:
        raise DtscalError("H[2,2] is zero for this pose (the camera centre lies on the ground plane)")
    return H / H[2, 2]


# =========================================================================== rendering core
def _plane_coords(rays: np.ndarray, R: np.ndarray, t: np.ndarray):
    """Plane coordinates hit by each ray: ``(p0, p1, ok)``, arrays shaped like ``rays[..., 0]``."""
    M = np.column_stack([R[:, 0], R[:, 1], t])
    Minv = np.linalg.inv(M)
    x, y = rays[..., 0], rays[..., 1]
    q0 = Minv[0, 0] * x + Minv[0, 1] * y + Minv[0, 2]
    q1 = Minv[1, 0] * x + Minv[1, 1] * y + Minv[1, 2]
    q2 = Minv[2, 0] * x + Minv[2, 1] * y + Minv[2, 2]
    ok = q2 > 1e-9
    q2 = np.where(ok, q2, 1.0)
    return q0 / q2, q1 / q2, ok


def _filtered_square_wave(u: np.ndarray, width: np.ndarray) -> np.ndarray:
    """Box-filtered square wave: +1 on cells with even ``floor(u)``, -1 on odd ones.

    ``width`` is the filter's width in cells (the sub-pixel footprint). Across each cell
    edge the value ramps linearly over ``width``: the exact box-filtered step for an edge
    aligned with the sub-pixel grid, and a close approximation otherwise. Point sampling
    instead would quantise edge positions to the sub-pixel grid (up to 1/(2s) pixel of
    corner error on a board facing the camera squarely).
    """
    k = np.rint(u)
    sign = np.where(np.mod(k, 2.0) == 0.0, 1.0, -1.0)
    return sign * np.clip((u - k) / np.maximum(width * 0.5, 1e-12), -1.0, 1.0)


def _footprint(a: np.ndarray) -> np.ndarray:
    """Extent of one sub-pixel in the units of ``a`` (a 2-D grid of plane coordinates)."""
    if a.shape[0] < 2 or a.shape[1] < 2:
        return np.zeros_like(a)
    gy, gx = np.gradient(a)
    return np.abs(gx) + np.abs(gy)


def _sheet_texture(bx: np.ndarray, by: np.ndarray, ok: np.ndarray, board: Board, sheet: Sheet,
                   shade: tuple[float, float, float], first_square_light: bool = False):
    """Reflectance (grey) and coverage of the sheet at board coordinates ``(bx, by)`` (metres).

    The squares are anti-aliased analytically (see :func:`_filtered_square_wave`) over
    each sub-pixel's footprint, then the sub-pixels are area-averaged by the caller.
    ``first_square_light``: the square between the first two inner corners of each axis (and so
    the corner square outside the first inner corner) is light, as on Duckietown's printed A3
    extrinsic pattern lying at its place (the first inner corner the near-right one: the corner
    square nearest the robot on its right is white; ``duckietown.md``); otherwise dark.
    """
    s = board.square
    cx, cy = board.centre[:2]
    on_paper = ok & (np.abs(bx - cx) <= sheet.width / 2) & (np.abs(by - cy) <= sheet.height / 2)
    u, v = bx / s, by / s  # in squares; squares occupy u in [-1, cols], v in [-1, rows]
    wu = np.where(ok, _footprint(u), 1.0)
    wv = np.where(ok, _footprint(v), 1.0)
    sq = _filtered_square_wave(u, wu) * _filtered_square_wave(v, wv)
    in_u = np.clip(0.5 + np.minimum(u + 1.0, board.cols - u) / np.maximum(wu, 1e-12), 0.0, 1.0)
    in_v = np.clip(0.5 + np.minimum(v + 1.0, board.rows - v) / np.maximum(wv, 1e-12), 0.0, 1.0)
    black = in_u * in_v * 0.5 * (1.0 + (-sq if first_square_light else sq))
    refl = sheet.paper + (sheet.ink - sheet.paper) * black
    # smooth uneven lighting across the sheet (a lamp to one side)
    base, gx, gy = shade
    light = base * (1.0 + gx * (bx - cx) / sheet.width + gy * (by - cy) / sheet.height)
    val = np.where(on_paper, refl * light, 0.0).astype(np.float32)
    return val, on_paper.astype(np.float32)


def _bilinear(img: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``img`` (h, w) sampled at pixel coordinates ``(x, y)`` with bilinear weights, the border replicated."""
    h, w = img.shape
    x = np.clip(x, 0.0, w - 1.0)
    y = np.clip(y, 0.0, h - 1.0)
    x0 = np.minimum(np.floor(x).astype(np.intp), w - 2)
    y0 = np.minimum(np.floor(y).astype(np.intp), h - 2)
    ax, ay = x - x0, y - y0
    top = img[y0, x0] * (1 - ax) + img[y0, x0 + 1] * ax
    bottom = img[y0 + 1, x0] * (1 - ax) + img[y0 + 1, x0 + 1] * ax
    return top * (1 - ay) + bottom * ay


class _CharucoTexture:
    """A ChArUco print: the chessboard squares drawn analytically like every board of the kit (so its corners are
    rendered exactly as a chessboard's), the ArUco markers sampled from OpenCV's own drawing of the board
    (``CharucoBoard.generateImage``: which squares hold which marker, the legacy layout included)."""

    #: bitmap resolution of the markers (pixels per metre): about one texel per sub-pixel on the sweep's boards
    PPM = 2000.0

    def __init__(self, board: CharucoBoard):
        self.board = board
        sx, sy = board.squares
        w, h = int(round(sx * board.square * self.PPM)), int(round(sy * board.square * self.PPM))
        self.bitmap = board.opencv_board().generateImage((w, h), marginSize=0).astype(np.float32) / 255.0
        # the corner square's colour in OpenCV's drawing decides the squares' parity (new and legacy layouts)
        c = int(round(0.5 * board.square * self.PPM))
        self.first_square_light = bool(self.bitmap[c, c] > 0.5)

    def __call__(self, bx, by, ok, sheet: Sheet, shade):
        b = self.board
        val, cov = _sheet_texture(bx, by, ok, b, sheet, shade, first_square_light=self.first_square_light)
        # board coordinates -> squares from the board's outer corner (the kit's origin is the first inner corner)
        qx, qy = bx / b.square + 1.0, by / b.square + 1.0
        half = 0.5 * b.marker / b.square + 1.0 / (b.square * self.PPM)
        fx, fy = qx - np.floor(qx) - 0.5, qy - np.floor(qy) - 0.5
        sx, sy = b.squares
        marker = ok & (np.abs(fx) < half) & (np.abs(fy) < half) & (qx >= 0) & (qy >= 0) & (qx < sx) & (qy < sy)
        if marker.any():
            mx = (qx[marker] * b.square * self.PPM - 0.5).astype(np.float32)
            my = (qy[marker] * b.square * self.PPM - 0.5).astype(np.float32)
            white = _bilinear(self.bitmap, mx, my)
            base, gx, gy = shade
            cx, cy = b.centre[:2]
            light = base * (1.0 + gx * (bx[marker] - cx) / sheet.width + gy * (by[marker] - cy) / sheet.height)
            refl = sheet.ink + (sheet.paper - sheet.ink) * white
            val = val.copy()
            val[marker] = (refl * light).astype(np.float32)
        return val, cov


def _downsample(a: np.ndarray, s: int) -> np.ndarray:
    if s == 1:
        return a
    h, w = a.shape[0] // s, a.shape[1] // s
    return cv2.resize(a, (w, h), interpolation=cv2.INTER_AREA)


def _bbox(camera: CameraModel, R, t, pts3: np.ndarray, pad: int = 3):
    """Pixel bounding box (x0, y0, x1, y1) of a planar region given by its outline, or None = whole image."""
    Z = (pts3 @ R.T + t)[:, 2]
    if np.any(Z <= 0.02):
        return None
    uv = project_points(pts3, R, t, camera.K, camera.dist)
    w, h = camera.size
    x0 = int(np.clip(np.floor(uv[:, 0].min()) - pad, 0, w))
    x1 = int(np.clip(np.ceil(uv[:, 0].max()) + pad + 1, 0, w))
    y0 = int(np.clip(np.floor(uv[:, 1].min()) - pad, 0, h))
    y1 = int(np.clip(np.ceil(uv[:, 1].max()) + pad + 1, 0, h))
    return x0, y0, x1, y1


def _line_kernel(blur) -> np.ndarray | None:
    """A normalised, point-symmetric streak kernel for a motion ``(dx, dy)`` pixels."""
    if blur is None:
        return None
    dx, dy = (float(b) for b in blur)
    length = math.hypot(dx, dy)
    if length < 0.75:
        return None
    r = int(math.ceil(length / 2)) + 1
    k = np.zeros((2 * r + 1, 2 * r + 1), dtype=np.float64)
    n = max(8, int(length * 8))
    for f in np.linspace(-0.5, 0.5, n):
        x, y = r + f * dx, r + f * dy
        x0, y0 = int(math.floor(x)), int(math.floor(y))
        ax, ay = x - x0, y - y0
        k[y0, x0] += (1 - ax) * (1 - ay)
        k[y0, x0 + 1] += ax * (1 - ay)
        k[y0 + 1, x0] += (1 - ax) * ay
        k[y0 + 1, x0 + 1] += ax * ay
    k = 0.5 * (k + k[::-1, ::-1])  # exactly point-symmetric: no shift of the image
    return (k / k.sum()).astype(np.float32)


@dataclass(frozen=True)
class Exposure:
    """Camera settings of one frame.

    ``brightness`` scales the scene radiance (light level times exposure time times gain),
    ``gain`` scales the noise, ``light`` is the colour of the light (B, G, R factors).
    """

    brightness: float = 1.0
    gain: float = 1.0
    light: tuple[float, float, float] = (0.93, 1.0, 1.05)
    #: strength of the lens vignetting (0 = none); the corner of the image gets ``1 / (1 + v)^2``
    vignetting: float = 0.30
    #: sigma of the lens blur, pixels
    lens_blur: float = 0.55
    #: sensor noise: variance = gain * (shot * signal + read^2 * gain)
    shot: float = 0.018
    read: float = 0.9


def _vignette(size: tuple[int, int], strength: float) -> np.ndarray:
    w, h = size
    u = (np.arange(w) - (w - 1) / 2) / ((w - 1) / 2)
    v = (np.arange(h) - (h - 1) / 2) / ((w - 1) / 2)
    r2 = (u[None, :] ** 2 + v[:, None] ** 2) / (1 + ((h - 1) / (w - 1)) ** 2)
    return (1.0 / (1.0 + strength * r2) ** 2).astype(np.float32)


def _finish(linear: np.ndarray, exposure: Exposure, rng: np.random.Generator | None) -> np.ndarray:
    """Lens blur, vignetting, exposure, sensor noise, quantisation: (H, W, 3) float32 -> uint8."""
    img = linear
    if exposure.lens_blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), exposure.lens_blur, borderType=cv2.BORDER_REFLECT)
    h, w = img.shape[:2]
    if exposure.vignetting > 0:
        img = img * _vignette((w, h), exposure.vignetting)[:, :, None]
    img = img * np.float32(exposure.brightness)
    if rng is not None:
        signal = np.clip(img, 0, 255)
        var = exposure.gain * (exposure.shot * signal + exposure.read ** 2 * exposure.gain)
        img = img + rng.standard_normal(img.shape, dtype=np.float32) * np.sqrt(var).astype(np.float32)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _render_layer(renderer: Renderer, R, t, texture: Callable, bbox):
    """Premultiplied colour (H, W, 3) and coverage (H, W) of one textured plane."""
    w, h = renderer.camera.size
    color = np.zeros((h, w, 3), dtype=np.float32)
    alpha = np.zeros((h, w), dtype=np.float32)
    x0, y0, x1, y1 = (0, 0, w, h) if bbox is None else bbox
    if x1 <= x0 or y1 <= y0:
        return color, alpha
    p0, p1, ok = renderer.plane_coords(R, t, (x0, y0, x1, y1))
    val, cov = texture(p0, p1, ok)
    if val.ndim == 2:
        val = val[:, :, None] * np.ones(3, dtype=np.float32)
    color[y0:y1, x0:x1] = renderer.downsample(np.ascontiguousarray(val * cov[:, :, None]))
    alpha[y0:y1, x0:x1] = renderer.downsample(cov)
    return color, alpha


def render_view(camera: CameraModel, board: Board, rvec, tvec, *, rng: np.random.Generator | None,
                background: np.ndarray | None = None, blur=None, exposure: Exposure | None = None,
                sheet: Sheet = A3_SHEET, shade: tuple[float, float, float] = (255.0, 0.0, 0.0),
                renderer: Renderer | None = None) -> tuple[np.ndarray, np.ndarray | None, bool]:
    """Render the camera's view of a board held at pose ``(rvec, tvec)``.

    Parameters
    ----------
    camera : the camera (usually :func:`synthetic_camera`)
    board : checkerboard geometry (object points define the board frame)
    rvec, tvec : board -> camera pose, (3,) each (``rvec`` may also be a (3, 3) matrix)
    rng : random generator for the sensor noise; None renders a noise-free image
    background : (H, W, 3) float32 static scene radiance (0..255); None: mid grey
    blur : (dx, dy) image motion of the board during the exposure, pixels; None: sharp
    exposure : camera settings (:class:`Exposure`); default: neutral
    shade : (level, gx, gy) light on the sheet: level in 0..255 units and relative gradients
        along the sheet's width and height
    renderer : a prepared :func:`make_renderer` for ``camera`` (built on the fly if None,
        which costs a few seconds)

    Returns
    -------
    image : (H, W, 3) uint8 BGR sensor image (before JPEG compression)
    corners : (N, 2) float64 true inner-corner pixels, or None if the board is not in view
    fully_visible : bool, see :func:`true_corners`
    """
    if renderer is None or renderer.camera is not camera:
        renderer = make_renderer(camera)
    exposure = Exposure() if exposure is None else exposure
    R = as_rotation(rvec)
    t = np.asarray(tvec, dtype=np.float64).reshape(3)
    w, h = camera.size
    if background is None:
        background = np.full((h, w, 3), 110.0, dtype=np.float32)
    if background.shape != (h, w, 3):
        raise DtscalError(f"background must be {h}x{w}x3 to match the camera, got {background.shape}")
    corners, visible = true_corners(camera, board, R, t)
    bbox = _bbox(camera, R, t, _sheet_outline(board, sheet))
    if isinstance(board, CharucoBoard):
        texture = _CharucoTexture(board)
        color, alpha = _render_layer(renderer, R, t, lambda a, b, ok: texture(a, b, ok, sheet, shade), bbox)
    else:
        color, alpha = _render_layer(
            renderer, R, t, lambda a, b, ok: _sheet_texture(a, b, ok, board, sheet, shade), bbox)
    kernel = _line_kernel(blur)
    if kernel is not None:
        color = cv2.filter2D(color, -1, kernel, borderType=cv2.BORDER_CONSTANT)
        alpha = cv2.filter2D(alpha, -1, kernel, borderType=cv2.BORDER_CONSTANT)
    light = np.asarray(exposure.light, dtype=np.float32)
    linear = color * light + (1.0 - alpha)[:, :, None] * background
    return _finish(linear.astype(np.float32), exposure, rng), corners, visible


def encode_jpeg(image: np.ndarray, quality: int = JPEG_QUALITY) -> bytes:
    """JPEG bytes of a BGR image as the camera node would publish them."""
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise DtscalError("OpenCV could not encode the frame as JPEG")
    return buf.tobytes()


def decode_jpeg(data: bytes) -> np.ndarray:
    """BGR image of JPEG bytes, through the kit's one guarded decoder (:func:`~dtscal_lib.sources.decode_image`)."""
    from .sources.decode import decode_image

    return decode_image(data)


# =========================================================================== scenes
def _smooth_noise(rng: np.random.Generator, size: tuple[int, int], cells: tuple[int, int]) -> np.ndarray:
    w, h = size
    small = rng.standard_normal((cells[1], cells[0])).astype(np.float32)
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)


def room_background(seed: int = DEFAULT_SEED, size: tuple[int, int] = dt.IMAGE_SIZE) -> np.ndarray:
    """A cluttered static scene (wall, window, poster, shelf, table, objects), (H, W, 3) float32.

    Values are scene radiance in 0..255 units before exposure and vignetting. Drawn at
    twice the size and area-averaged, so edges are anti-aliased.
    """
    rng = np.random.default_rng([seed, _STREAM_SCENE, 0])
    w, h = size
    S = 2
    W, Hh = w * S, h * S
    img = np.zeros((Hh, W, 3), dtype=np.float32)
    horizon = int(0.56 * Hh)
    yy = np.arange(Hh, dtype=np.float32)[:, None]
    # wall: warm beige with a vertical light gradient and blotches
    wall = np.array([150, 170, 182], dtype=np.float32)
    img[:horizon] = wall * (0.85 + 0.25 * (1 - yy[:horizon] / horizon))[:, :, None]
    img[:horizon] *= (1 + 0.05 * _smooth_noise(rng, (W, horizon), (9, 5)))[:, :, None]
    # window (bright), with mullions
    cv2.rectangle(img, (int(0.06 * W), int(0.05 * Hh)), (int(0.30 * W), int(0.40 * Hh)), (245, 240, 228), -1)
    cv2.line(img, (int(0.18 * W), int(0.05 * Hh)), (int(0.18 * W), int(0.40 * Hh)), (95, 100, 110), 7)
    cv2.line(img, (int(0.06 * W), int(0.22 * Hh)), (int(0.30 * W), int(0.22 * Hh)), (95, 100, 110), 7)
    cv2.rectangle(img, (int(0.06 * W), int(0.05 * Hh)), (int(0.30 * W), int(0.40 * Hh)), (80, 85, 95), 9)
    # poster with blobs
    px0, py0, px1, py1 = int(0.62 * W), int(0.08 * Hh), int(0.86 * W), int(0.42 * Hh)
    cv2.rectangle(img, (px0, py0), (px1, py1), (60, 120, 200), -1)
    for _ in range(6):
        c = (int(rng.integers(px0 + 20, px1 - 20)), int(rng.integers(py0 + 20, py1 - 20)))
        col = tuple(float(v) for v in rng.uniform(30, 240, 3))
        cv2.circle(img, c, int(rng.integers(12, 45)), col, -1, cv2.LINE_AA)
    cv2.rectangle(img, (px0, py0), (px1, py1), (40, 40, 40), 5)
    # shelf with books
    sy = int(0.47 * Hh)
    cv2.rectangle(img, (int(0.36 * W), sy), (int(0.58 * W), sy + 14), (60, 90, 120), -1)
    x = int(0.37 * W)
    while x < int(0.56 * W):
        bw = int(rng.integers(14, 34))
        bh = int(rng.integers(70, 130))
        col = tuple(float(v) for v in rng.uniform(30, 200, 3))
        cv2.rectangle(img, (x, sy - bh), (x + bw, sy), col, -1)
        x += bw + 3
    # table: wood with grain
    wood = np.array([70, 110, 150], dtype=np.float32)
    grain = 0.85 + 0.08 * np.sin(np.arange(Hh - horizon, dtype=np.float32)[:, None] * 0.9
                                 + 3 * _smooth_noise(rng, (W, Hh - horizon), (7, 4)))
    img[horizon:] = wood * grain[:, :, None]
    img[horizon:] *= (1 + 0.06 * _smooth_noise(rng, (W, Hh - horizon), (30, 8)))[:, :, None]
    cv2.line(img, (0, horizon), (W, horizon), (40, 60, 80), 6)
    # objects on the table: a mug, a laptop, a rubber duck, a cable, a notebook
    cv2.rectangle(img, (int(0.80 * W), int(0.66 * Hh)), (int(0.88 * W), int(0.82 * Hh)), (40, 40, 170), -1)
    cv2.ellipse(img, (int(0.84 * W), int(0.66 * Hh)), (int(0.04 * W), 10), 0, 0, 360, (30, 30, 120), -1)
    cv2.ellipse(img, (int(0.89 * W), int(0.74 * Hh)), (18, 28), 0, -90, 90, (40, 40, 170), 8)
    lap = np.array([[0.05, 0.93], [0.30, 0.93], [0.26, 0.70], [0.09, 0.70]]) * [W, Hh]
    cv2.fillPoly(img, [lap.astype(np.int32)], (55, 55, 60), cv2.LINE_AA)
    cv2.fillPoly(img, [(lap * [1, 1] + [0, 0]).astype(np.int32)[[2, 3]].reshape(-1, 1, 2)], (0, 0, 0))
    dx, dy = int(0.52 * W), int(0.86 * Hh)
    cv2.ellipse(img, (dx, dy), (44, 30), 0, 0, 360, (40, 215, 245), -1, cv2.LINE_AA)  # body (yellow)
    cv2.circle(img, (dx + 30, dy - 36), 22, (40, 215, 245), -1, cv2.LINE_AA)  # head
    cv2.ellipse(img, (dx + 55, dy - 32), (14, 6), 0, 0, 360, (30, 120, 240), -1, cv2.LINE_AA)  # beak
    cv2.circle(img, (dx + 36, dy - 42), 4, (10, 10, 10), -1, cv2.LINE_AA)
    pts = np.column_stack([np.linspace(0.33, 0.75, 40) * W,
                           (0.97 - 0.05 * np.sin(np.linspace(0, 7, 40))) * Hh]).astype(np.int32)
    cv2.polylines(img, [pts], False, (25, 25, 25), 6, cv2.LINE_AA)
    nb = np.array([[0.60, 0.70], [0.76, 0.69], [0.78, 0.80], [0.61, 0.82]]) * [W, Hh]
    cv2.fillPoly(img, [nb.astype(np.int32)], (180, 200, 210), cv2.LINE_AA)
    for k in range(5):
        y = 0.715 + 0.02 * k
        cv2.line(img, (int(0.62 * W), int(y * Hh)), (int(0.76 * W), int((y - 0.004) * Hh)), (160, 120, 90), 2)
    img = cv2.GaussianBlur(img, (0, 0), 1.2)
    return cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA).astype(np.float32)


def scene_through_lens(renderer: Renderer, seed: int = DEFAULT_SEED) -> np.ndarray:
    """The room, seen through the camera's lens: (H, W, 3) float32 radiance.

    :func:`room_background` draws the room as a pinhole picture: its straight edges are
    straight on that canvas. Here the canvas is spread over the camera's whole field of view
    in *undistorted* normalized coordinates, and every sub-pixel samples it along its ray.
    So the room is bent by the lens like the board is, and rectifying a recorded frame
    straightens the window frames and the table edge as it straightens the board.
    """
    cam = renderer.camera
    w, h = cam.size
    s = renderer.supersample
    x, y = renderer.rays[..., 0], renderer.rays[..., 1]
    # the canvas covers the field of view with a small margin; 1.25x the image for detail
    cw, ch = int(round(1.25 * w)), int(round(1.25 * h))
    canvas = room_background(seed, (cw, ch))
    x0, x1 = float(x.min()), float(x.max())
    y0, y1 = float(y.min()), float(y.max())
    pad_x, pad_y = 0.02 * (x1 - x0), 0.02 * (y1 - y0)
    map_x = ((x - x0 + pad_x) / (x1 - x0 + 2 * pad_x) * (cw - 1)).astype(np.float32)
    map_y = ((y - y0 + pad_y) / (y1 - y0 + 2 * pad_y) * (ch - 1)).astype(np.float32)
    sub = cv2.remap(canvas, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    return _downsample(np.ascontiguousarray(sub), s).astype(np.float32)


# --------------------------------------------------------------------------- the hand-held sweep
#: key poses of the hand-held sweep: (frames from the previous key, frames held,
#: board-centre pixel u, v, distance z [m], pitch, yaw, roll [deg]); None = no board in view.
#: Angles are relative to facing the camera squarely: +pitch turns the board's top towards the
#: camera, +yaw its right side towards the camera, roll turns it in its own plane.
_SWEEP: tuple = (
    (0, 10, None),                                   # empty scene: the board is not there yet
    (1, 0, (760, 250, 0.45, 0, 15, 0)),              # brought in from the right (partial)
    (12, 2, (330, 240, 0.45, 0, 0, 0)),
    (9, 2, (115, 235, 0.45, 5, 25, 3)),              # left
    (8, 2, (120, 92, 0.50, -20, 25, 8)),             # top-left
    (8, 2, (320, 88, 0.50, -30, 0, 0)),              # top
    (8, 2, (525, 95, 0.50, -20, -25, -8)),           # top-right
    (8, 2, (535, 240, 0.45, 0, -30, 0)),             # right
    (8, 2, (528, 392, 0.50, 25, -22, 6)),            # bottom-right
    (8, 2, (318, 398, 0.50, 30, 0, 0)),              # bottom
    (8, 2, (112, 388, 0.50, 20, 25, -6)),            # bottom-left
    (9, 1, (-60, 260, 0.45, 0, 10, 0)),              # out through the left edge (partial)
    (10, 2, (320, 240, 0.80, 0, 0, 12)),              # far (too small for OpenCV's FAST_CHECK)
    (8, 2, (165, 175, 0.58, 10, 20, 18)),
    (8, 2, (470, 300, 0.56, -15, -20, -12)),
    (8, 2, (335, 125, 0.55, 34, 5, 0)),
    (8, 2, (300, 360, 0.55, -34, -5, 4)),
    (9, 2, (300, 230, 0.36, 0, 40, 0)),              # strong tilts
    (9, 2, (340, 250, 0.36, 0, -40, 5)),
    (9, 2, (320, 240, 0.36, 38, 0, -5)),
    (9, 2, (320, 235, 0.36, -38, 0, 0)),
    (9, 2, (300, 250, 0.32, 30, 30, 10)),
    (9, 2, (340, 230, 0.32, -30, 30, -4)),
    (9, 2, (330, 250, 0.32, 30, -30, 4)),
    (9, 2, (310, 230, 0.32, -30, -30, -10)),
    (9, 1, (320, 700, 0.40, 10, 0, 0)),              # lowered out of view through the bottom
    (0, 8, None),                                    # no board
    (1, 0, (330, 680, 0.30, 0, 0, 0)),               # back in from the bottom (partial)
    (9, 2, (322, 245, 0.185, 0, 0, 0)),              # near: big in the image
    (8, 2, (300, 240, 0.18, 0, 22, 4)),
    (8, 2, (335, 238, 0.20, -22, 0, -8)),
    (8, 2, (330, 250, 0.205, 18, -14, 6)),
    (8, 1, (180, 250, 0.18, 0, 10, 0)),              # near, sliding off the left edge (partial)
    (9, 2, (96, 300, 0.27, 5, 42, 6)),               # edges, tilted
    (9, 2, (548, 180, 0.27, 22, -40, -6)),
    (9, 2, (105, 82, 0.50, -10, 20, 22)),            # far corners, rolled
    (9, 2, (540, 400, 0.50, 15, -15, -20)),
    (8, 2, (535, 85, 0.48, -30, -30, 0)),
    (9, 2, (105, 395, 0.48, 30, 30, 0)),
    (9, 1, (820, 240, 0.50, 0, 0, 0)),               # out through the right edge
    (0, 6, None),                                    # empty again
)


def _sweep_frames() -> tuple[int, list]:
    """Timeline of the sweep: number of frames and the board segments.

    Returns
    -------
    n_frames : int
    segments : list of ``(t_first, t_last, interpolator)``; ``interpolator(t)`` gives the
        key parameters ``(u, v, z, pitch, yaw, roll)`` at frame time ``t`` (monotone cubic,
        so holds are exact and moves start and stop smoothly). Frames outside every
        segment have no board.
    """
    from scipy.interpolate import PchipInterpolator

    segments = []
    cur: list[tuple[float, tuple]] = []
    t = 0  # first frame not yet assigned

    def close():
        tt = np.array([k for k, _ in cur], dtype=np.float64)
        pp = np.array([p for _, p in cur], dtype=np.float64)
        segments.append((tt[0], tt[-1], PchipInterpolator(tt, pp, axis=0)))
        cur.clear()
        return int(tt[-1]) + 1

    for step, hold, params in _SWEEP:
        if params is None:
            if cur:
                t = close()
            t += hold
            continue
        key = cur[-1][0] + step if cur else float(t)
        cur.append((key, params))
        if hold:
            cur.append((key + hold, params))
    if cur:
        t = close()
    return t, segments


def _tremor(seed: int):
    """Small smooth hand tremor: offsets (du, dv px; dz m; pitch, yaw, roll deg) as a function of time."""
    rng = np.random.default_rng([seed, _STREAM_SCENE, 1])
    freqs = rng.uniform(0.6, 3.5, (6, 3))  # Hz
    phases = rng.uniform(0, 2 * np.pi, (6, 3))
    amps = np.array([1.2, 1.2, 0.0015, 0.35, 0.35, 0.3]) / 2.0

    def at(t_s: float) -> np.ndarray:
        return amps * np.sin(2 * np.pi * freqs * t_s + phases).sum(axis=1) / 1.5

    return at


def _pose_from_params(camera: CameraModel, board: Board, p) -> tuple[np.ndarray, np.ndarray]:
    """Board pose from sweep parameters ``(u, v, z, pitch, yaw, roll)``.

    The centre of the corner grid is seen at pixel ``(u, v)`` at depth ``z`` (metres along
    the optical axis). With zero angles the board faces the camera squarely (its normal
    along the viewing ray to its centre, its rows level); pitch, yaw and roll (degrees)
    then tilt it about its own horizontal, vertical and normal axes, as a hand would.
    """
    u, v, z, pitch, yaw, roll = (float(a) for a in p)
    xy = undistort_normalized(pixel_to_normalized([[u, v]], camera.K), camera.dist)[0]
    C = z * np.array([xy[0], xy[1], 1.0])
    zb = C / np.linalg.norm(C)
    xb = np.array([1.0, 0.0, 0.0]) - zb[0] * zb
    xb /= np.linalg.norm(xb)
    R_face = np.column_stack([xb, np.cross(zb, xb), zb])
    R = R_face @ _rot("z", roll) @ _rot("y", yaw) @ _rot("x", pitch)
    return R, C - R @ board.centre


@dataclass(frozen=True)
class _SweepPlan:
    n_frames: int
    segments: list

    def params(self, t: float) -> np.ndarray | None:
        for t0, t1, f in self.segments:
            if t0 - 1e-9 <= t <= t1 + 1e-9:
                return f(np.clip(t, t0, t1))
        return None


def _exposure_at(seed: int, t_s: float) -> tuple[Exposure, float]:
    """Auto-exposure drift: (camera settings, exposure time as a fraction of the frame interval)."""
    rng = np.random.default_rng([seed, _STREAM_SCENE, 2])
    ph = rng.uniform(0, 2 * np.pi, 3)
    light = 1.0 + 0.10 * math.sin(2 * math.pi * t_s / 6.5 + ph[0]) + 0.05 * math.sin(2 * math.pi * t_s / 2.3 + ph[1])
    # the auto exposure compensates slowly and imperfectly: brightness follows the light a little
    brightness = 1.0 + 0.6 * (light - 1.0) + 0.04 * math.sin(2 * math.pi * t_s / 3.1 + ph[2])
    gain = 1.0 + 2.0 * max(0.0, 1.05 - light)  # darker -> more analog gain -> more noise
    exp_frac = 0.10 + 0.35 * max(0.0, 1.08 - light)  # and a longer exposure
    return Exposure(brightness=brightness, gain=gain), exp_frac


def intrinsic_session(seed: int = DEFAULT_SEED, *, frames: Iterable[int] | None = None,
                      renderer: Renderer | None = None, board: Board = DUCKIETOWN_BOARD,
                      progress: Callable | None = None) -> list[SynthFrame]:
    """The hand-held sweep for intrinsic calibration (about 9 s at 30 fps).

    Parameters
    ----------
    seed : random seed (sensor noise, tremor, scene clutter)
    frames : only render these frame indices (the others are skipped); default: all
    renderer : a prepared :func:`make_renderer` of :func:`synthetic_camera`
    progress : optional wrapper for the frame iterator (e.g. ``tqdm``)

    Returns
    -------
    list of :class:`SynthFrame`, stamps ``STAMP0_NS + index / 30 s``
    """
    camera = synthetic_camera() if renderer is None else renderer.camera
    renderer = make_renderer(camera) if renderer is None else renderer
    n, segments = _sweep_frames()
    plan = _SweepPlan(n, segments)
    background = scene_through_lens(renderer, seed)
    tremor = _tremor(seed)
    fps = dt.FPS
    idx = range(n) if frames is None else sorted(set(int(i) for i in frames))
    for i in idx:
        if not 0 <= i < n:
            raise DtscalError(f"frame {i} is outside the session (0..{n - 1})")
    out = []
    it = progress(list(idx)) if progress else idx
    for i in it:
        t_s = i / fps
        exposure, exp_frac = _exposure_at(seed, t_s)
        rng = np.random.default_rng([seed, _STREAM_INTRINSIC, i])
        p = plan.params(float(i))
        stamp = STAMP0_NS + round(i * 1e9 / fps)
        if p is None:
            img = _finish(background.copy(), exposure, rng)
            jpeg = encode_jpeg(img)
            out.append(SynthFrame(i, stamp, decode_jpeg(jpeg), jpeg, None, None, None, False, 0.0))
            continue
        p = np.asarray(p) + tremor(t_s)
        R, t = _pose_from_params(camera, board, p)
        # motion during the exposure, centred on the frame time
        blur = None
        blur_len = 0.0
        half = 0.5 * exp_frac
        pa, pb = plan.params(i - half), plan.params(i + half)
        if pa is not None and pb is not None:
            Ra, ta = _pose_from_params(camera, board, np.asarray(pa) + tremor((i - half) / fps))
            Rb, tb = _pose_from_params(camera, board, np.asarray(pb) + tremor((i + half) / fps))
            centre = board.centre[None, :]
            try:
                ua = project_points(centre, Ra, ta, camera.K, camera.dist)[0]
                ub = project_points(centre, Rb, tb, camera.K, camera.dist)[0]
                blur = ub - ua
                blur_len = float(np.hypot(*blur))
                if blur_len < 0.75:
                    blur, blur_len = None, 0.0
            except DtscalError:
                blur = None
        tilt = R[:, 2]
        shade = (212.0 + 40.0 * float(np.clip(-tilt[1], -1, 1)), 0.12, -0.10)
        img, corners, visible = render_view(camera, board, _rvec(R), t, rng=rng, background=background,
                                            blur=blur, exposure=exposure, shade=shade, renderer=renderer)
        jpeg = encode_jpeg(img)
        out.append(SynthFrame(i, stamp, decode_jpeg(jpeg), jpeg, _rvec(R), t.copy(), corners, visible,
                              round(blur_len, 3)))
    return out


def intrinsic_frame_count() -> int:
    """Number of frames in the intrinsic session."""
    return _sweep_frames()[0]


#: the board of the bundled ChArUco recording: 8x6 squares of 45 mm (360 x 270 mm, an A3 sheet as the Duckietown
#: board is), 27 mm DICT_4X4_50 markers. Markers of 0.6 of the square leave each corner a marker-free window
#: (dtscal_lib.detect.charuco: 0.07 px rms corners here, against 0.16 px with markers of 0.76 of the square)
CHARUCO_BOARD = CharucoBoard.from_squares(8, 6, 0.045, 0.027, "4x4_50")
#: the ChArUco recording keeps every third frame of the sweep (10 frames a second, 3 MB)
CHARUCO_EVERY = 3


def charuco_session(seed: int = DEFAULT_SEED, *, renderer: Renderer | None = None,
                    progress: Callable | None = None) -> list[SynthFrame]:
    """The hand-held sweep of :func:`intrinsic_session` with :data:`CHARUCO_BOARD`, every third frame: the
    larger board leaves the image at the sweep's edges, where only a ChArUco board still gives corners."""
    frames = range(0, intrinsic_frame_count(), CHARUCO_EVERY)
    return intrinsic_session(seed, frames=frames, renderer=renderer, board=CHARUCO_BOARD, progress=progress)


# --------------------------------------------------------------------------- the extrinsic capture
@dataclass(frozen=True)
class RobotCamera:
    """Where the camera sits on the robot (robot frame: x forward, y left, z up; metres, degrees)."""

    x: float = 0.062      # ahead of the wheel axis
    y: float = 0.0
    height: float = 0.104
    pitch: float = 18.0   # down from horizontal
    yaw: float = 0.8      # small mounting errors, left positive
    roll: float = -0.6

    def pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Robot (ground) frame -> camera frame: ``(R, t)`` with ``Xc = R X + t``."""
        p = math.radians(self.pitch)
        # camera axes in the robot frame for a level camera pitched down by p:
        z_c = np.array([math.cos(p), 0.0, -math.sin(p)])  # optical axis
        x_c = np.array([0.0, -1.0, 0.0])                  # image right = robot's right
        y_c = np.cross(z_c, x_c)                           # image down
        R_level = np.vstack([x_c, y_c, z_c])
        # mounting errors: yaw about the robot's z, roll about the optical axis
        R = _rot("z", self.roll) @ R_level @ _rot("z", self.yaw).T
        C = np.array([self.x, self.y, self.height])
        return R, -R @ C


#: board frame -> robot frame for the Duckietown placement (board x -> robot y, board y -> robot x)
_BOARD_TO_GROUND = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def _floor_texture(seed: int):
    """Duckietown mat around the robot: dark tiles, white right-lane line, yellow dashed centre line."""
    rng = np.random.default_rng([seed, _STREAM_SCENE, 3])
    grain = rng.standard_normal((256, 256)).astype(np.float32)
    grain = cv2.GaussianBlur(grain, (0, 0), 1.0)
    grain = np.tile(grain, (2, 2))

    def tex(X: np.ndarray, Y: np.ndarray, ok: np.ndarray):
        on_mat = ok & (X > -0.4) & (X < 1.6) & (np.abs(Y) < 1.2)
        gx = np.mod(X * 400.0, 256.0).astype(np.float32)  # 2.5 mm texture cells
        gy = np.mod(Y * 400.0, 256.0).astype(np.float32)
        g = cv2.remap(grain, gx, gy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
        base = 0.09 * (1.0 + 0.25 * g)
        col = np.repeat(base[..., None], 3, axis=-1)
        white = (Y < -0.225) & (Y > -0.273)
        yellow = (Y > 0.235) & (Y < 0.26) & (np.mod(X + 0.02, 0.1) < 0.05)
        col[white] = (0.78, 0.8, 0.8)
        col[yellow] = (0.05, 0.62, 0.78)
        # tile seams every 0.585 m
        seam = ((np.abs(np.mod(X + 0.2925, 0.585) - 0.2925) < 0.002)
                | (np.abs(np.mod(Y + 0.2925, 0.585) - 0.2925) < 0.002))
        col[seam] *= 0.5
        return col.astype(np.float32) * 255.0, on_mat.astype(np.float32)

    return tex


def extrinsic_capture(seed: int = DEFAULT_SEED, *, n_frames: int = 5, mount: RobotCamera = RobotCamera(),
                      renderer: Renderer | None = None, board: Board = DUCKIETOWN_BOARD,
                      sheet: Sheet = A3_SHEET) -> tuple[list[SynthFrame], dict]:
    """The robot standing on the mat with the board flat at the Duckietown placement.

    The robot does not move: the frames differ only in sensor noise and a slight exposure
    drift. The board's inner corners sit at :func:`boards.ground_points` (near row at
    x = 0.191 m, y from -0.093 to +0.093 m).

    Returns
    -------
    frames : list of :class:`SynthFrame` (``rvec, tvec`` = board -> camera)
    truth : dict with the camera mount, the robot -> camera pose, the exact homography
        (rectified with ``duckietown.default_P()``) and the ground points
    """
    if n_frames < 1:
        raise DtscalError(f"n_frames must be at least 1, got {n_frames}")
    camera = synthetic_camera() if renderer is None else renderer.camera
    renderer = make_renderer(camera) if renderer is None else renderer
    R_cg, t_cg = mount.pose()
    g0 = np.array([*ground_points(board)[0], 0.0])  # board origin (first corner) on the ground
    R_cb = R_cg @ _BOARD_TO_GROUND
    t_cb = R_cg @ g0 + t_cg
    corners, visible = true_corners(camera, board, R_cb, t_cb)
    if corners is None or not visible:
        raise DtscalError("the extrinsic board placement is not fully visible with this camera mount")

    # static scene: floor (with the sheet lying on it) over the room background
    background = scene_through_lens(renderer, seed)
    floor = _floor_texture(seed)

    def tex(X, Y, ok):
        col, cov = floor(X, Y, ok)
        bx, by = Y - g0[1], X - g0[0]
        # Duckietown's printed pattern as it lies: the corner square nearest the robot on its right is white
        val, on_paper = _sheet_texture(bx, by, ok, board, sheet, (225.0, 0.05, -0.08), first_square_light=True)
        paper = on_paper > 0
        col[paper] = val[paper][:, None] * np.ones(3, dtype=np.float32)
        return col, np.maximum(cov, on_paper)

    color, alpha = _render_layer(renderer, R_cg, t_cg, tex, None)
    exp0 = Exposure()
    linear = (color * np.asarray(exp0.light, dtype=np.float32) + (1 - alpha)[:, :, None] * background)
    linear = linear.astype(np.float32)
    frames = []
    base = STAMP0_NS + EXTRINSIC_OFFSET_NS
    for i in range(n_frames):
        rng = np.random.default_rng([seed, _STREAM_EXTRINSIC, i])
        exposure = Exposure(brightness=1.0 + 0.03 * math.sin(1.3 * i), gain=1.2)
        img = _finish(linear, exposure, rng)
        jpeg = encode_jpeg(img)
        frames.append(SynthFrame(i, base + round(i * 1e9 / dt.FPS), decode_jpeg(jpeg), jpeg,
                                 _rvec(R_cb), t_cb.copy(), corners.copy(), True, 0.0))
    H = ground_truth_homography(camera, R_cg, t_cg, dt.default_P())
    truth = {
        "camera_x_m": mount.x,
        "camera_y_m": mount.y,
        "camera_height_m": mount.height,
        "camera_pitch_deg": mount.pitch,
        "camera_yaw_deg": mount.yaw,
        "camera_roll_deg": mount.roll,
        "ground_to_camera_rvec": _rvec(R_cg),
        "ground_to_camera_tvec": t_cg,
        "homography": H,
        "homography_P": dt.default_P(),
        "ground_points": ground_points(board),
        "board_origin_ground": g0[:2].copy(),
    }
    return frames, truth


# =========================================================================== storage
def _write_bag(path: Path, topic: str, frame_id: str, frames: list[SynthFrame]) -> None:
    """Write the frames as a ROS 1 bag of ``sensor_msgs/CompressedImage`` (what ``rosbag record`` writes)."""
    from .sources import write_compressed_image_bag

    write_compressed_image_bag(path, topic, ((int(f.stamp_ns), f.jpeg) for f in frames), frame_id=frame_id)


def _list(a, nd: int = 6):
    if a is None:
        return None
    arr = np.asarray(a, dtype=np.float64)
    return np.round(arr, nd).tolist()


def _frame_entry(f: SynthFrame) -> dict:
    return {
        "index": int(f.index),
        "stamp_ns": int(f.stamp_ns),
        "board_visible": bool(f.visible),
        "rvec": _list(f.rvec, 9),
        "tvec": _list(f.tvec, 9),
        "blur_px": float(f.blur_px),
        "corners": _list(f.corners, 6),
    }


def generate_charuco(out_dir: Path, *, robot: str = SYNTH_ROBOT, seed: int | None = DEFAULT_SEED,
                     renderer: Renderer | None = None) -> dict[str, Path]:
    """Write the ChArUco recording: ``session/charuco.bag`` (the camera topic of :func:`generate`) and
    ``session/charuco.yaml`` (the board as printed, the camera, each frame's pose and true corners)."""
    import yaml

    seed = DEFAULT_SEED if seed is None else int(seed)
    session = Path(out_dir) / "session"
    session.mkdir(parents=True, exist_ok=True)
    renderer = make_renderer(synthetic_camera()) if renderer is None else renderer
    frames = charuco_session(seed, renderer=renderer)
    topic = dt.IMAGE_TOPIC.format(robot=robot)
    paths = {"charuco_bag": session / "charuco.bag", "charuco_truth": session / "charuco.yaml"}
    _write_bag(paths["charuco_bag"], topic, f"{robot}/camera_optical_frame", frames)
    b, cam = CHARUCO_BOARD, renderer.camera
    truth = {
        "synthetic": True,
        "description": "SYNTHETIC ChArUco sweep rendered by dtscal_lib.synth.generate_charuco; exact ground truth",
        "generator": {"module": "dtscal_lib.synth", "command": "dtscal synth --out data --charuco", "seed": seed,
                      "every": CHARUCO_EVERY, "opencv": cv2.__version__},
        "topic": topic,
        "board": {"squares": list(b.squares), "square": b.square, "marker": b.marker, "dictionary": b.dictionary,
                  "legacy": b.legacy, "flags": f"--charuco {b.squares[0]}x{b.squares[1]} --square {b.square:g} "
                                               f"--marker {b.marker:g} --aruco-dict {b.dictionary}"},
        "camera": {"image_width": cam.size[0], "image_height": cam.size[1], "distortion_model": cam.model,
                   "K": _list(cam.K, 12), "dist": _list(cam.dist, 12)},
        "frames": [_frame_entry(f) for f in frames],
    }
    paths["charuco_truth"].write_text("# SYNTHETIC ChArUco session; generated, do not edit by hand.\n"
                                      + yaml.safe_dump(truth, sort_keys=False, default_flow_style=None, width=120),
                                      encoding="utf-8")
    return paths


def generate(out_dir: Path, *, robot: str = SYNTH_ROBOT, seed: int | None = DEFAULT_SEED,
             progress: bool = True) -> dict[str, Path]:
    """Render the whole synthetic session and write it under ``out_dir``.

    Writes ``session/intrinsics.bag``, ``session/extrinsics.bag`` (topic
    ``/<robot>/camera_node/image/compressed``) and ``session/truth.yaml``.
    Regenerating with the same seed writes byte-identical files.

    Returns
    -------
    dict name -> written path
    """
    import yaml

    seed = DEFAULT_SEED if seed is None else int(seed)
    if not robot or not all(c.isalnum() or c == "_" for c in robot):
        raise DtscalError(f"robot name must be letters, digits or '_', got {robot!r}")
    out_dir = Path(out_dir)
    session = out_dir / "session"
    session.mkdir(parents=True, exist_ok=True)
    wrap = None
    if progress:
        import sys

        from tqdm import tqdm

        def wrap(items):
            return tqdm(items, desc="rendering", unit="frame", file=sys.stderr, leave=False, disable=None)

    renderer = make_renderer(synthetic_camera())
    intr = intrinsic_session(seed, renderer=renderer, progress=wrap)
    extr, etruth = extrinsic_capture(seed, renderer=renderer)
    topic = dt.IMAGE_TOPIC.format(robot=robot)
    frame_id = f"{robot}/camera_optical_frame"
    paths = {"intrinsics_bag": session / "intrinsics.bag", "extrinsics_bag": session / "extrinsics.bag",
             "truth": session / "truth.yaml"}
    _write_bag(paths["intrinsics_bag"], topic, frame_id, intr)
    _write_bag(paths["extrinsics_bag"], topic, frame_id, extr)

    cam = renderer.camera
    board = DUCKIETOWN_BOARD
    truth = {
        "synthetic": True,
        "description": ("SYNTHETIC recording rendered by dtscal_lib.synth; not a real robot. "
                        "Camera = the Duckiebot's shipped default intrinsics; every value below is exact "
                        "ground truth for the frames in the bags."),
        "generator": {"module": "dtscal_lib.synth", "command": "dtscal synth --out data", "seed": seed,
                      "supersample": renderer.supersample, "jpeg_quality": JPEG_QUALITY,
                      "opencv": cv2.__version__},
        "robot": robot,
        "topic": topic,
        "frame_id": frame_id,
        "fps": dt.FPS,
        "camera": {
            "image_width": cam.size[0], "image_height": cam.size[1],
            "distortion_model": cam.model,
            "K": _list(cam.K, 12), "dist": _list(cam.dist, 12), "P": _list(cam.P, 12),
        },
        "board": {"cols": board.cols, "rows": board.rows, "square": board.square,
                  "sheet_m": [A3_SHEET.width, A3_SHEET.height],
                  "corner_order": "OpenCV row-major: x along a row of 7, then 5 rows"},
        "pose_convention": "rvec/tvec: board frame -> camera frame, Xc = R(rvec) X + tvec, metres",
        "intrinsics": {
            "bag": "session/intrinsics.bag",
            "n_frames": len(intr),
            "n_board_visible": int(sum(f.visible for f in intr)),
            "frames": [_frame_entry(f) for f in intr],
        },
        "extrinsics": {
            "bag": "session/extrinsics.bag",
            "n_frames": len(extr),
            "camera_x_m": etruth["camera_x_m"],
            "camera_y_m": etruth["camera_y_m"],
            "camera_height_m": etruth["camera_height_m"],
            "camera_pitch_deg": etruth["camera_pitch_deg"],
            "camera_yaw_deg": etruth["camera_yaw_deg"],
            "camera_roll_deg": etruth["camera_roll_deg"],
            "ground_to_camera_rvec": _list(etruth["ground_to_camera_rvec"], 12),
            "ground_to_camera_tvec": _list(etruth["ground_to_camera_tvec"], 12),
            "homography_note": "rectified pixel (initUndistortRectifyMap(K, D, I, P) with the P below) -> "
                               "ground metres (x forward, y left), row-major, H[2][2] = 1",
            "homography": _list(etruth["homography"].ravel(), 15),
            "homography_P": _list(etruth["homography_P"], 12),
            "ground_points": _list(etruth["ground_points"], 9),
            "frames": [_frame_entry(f) for f in extr],
        },
    }
    text = yaml.safe_dump(truth, sort_keys=False, default_flow_style=None, width=120)
    header = ("# SYNTHETIC Duckiebot session: exact ground truth for intrinsics.bag and extrinsics.bag.\n"
              "# Generated by `dtscal synth --out data`; do not edit by hand.\n")
    safe_write.write_text(paths["truth"], header + text, what="recording's ground truth")
    return paths


# =========================================================================== stress set
@dataclass(frozen=True)
class PrintedBoard:
    """How a real printed board differs from the ideal pattern on a wide white margin.

    Sizes in squares of the board. ``outer`` is the width of the outermost squares (1 = full;
    real boards are often cut through them), ``margin`` the white paper left beyond the
    squares before the board's physical edge, ``outline`` an optional printed black frame
    ``(gap, thickness)`` around the squares.
    """

    outer: float = 1.0
    margin: float = 1.0
    outline: tuple[float, float] | None = None
    paper: float = 0.86
    ink: float = 0.05


#: the stress cases :func:`render_stress_case` can render
STRESS_KINDS: tuple[str, ...] = ("narrow_outer", "thick_outline", "edge_clutter", "perspective", "distortion",
                                 "blur", "noise", "low_contrast", "small_far")


@dataclass(frozen=True, eq=False)
class StressCase:
    """One rendered stress frame with its exact truth.

    ``corners`` are :func:`true_corners` of the pose (OpenCV row-major order of ``board``),
    ``visible`` whether the whole board is in the picture (see :func:`true_corners`).
    """

    kind: str
    seed: int
    image: np.ndarray
    corners: np.ndarray | None
    visible: bool
    board: Board
    camera: CameraModel
    rvec: np.ndarray
    tvec: np.ndarray


def stress_camera(kind: str) -> CameraModel:
    """The camera of a stress case: the Duckiebot lens, or a stronger barrel lens for ``"distortion"``."""
    if kind == "distortion":
        return CameraModel(dt.default_K(), np.array([-0.33, 0.11, 0.002, -0.002, 0.0]), dt.IMAGE_SIZE)
    return synthetic_camera()


def _printed_texture(bx: np.ndarray, by: np.ndarray, ok: np.ndarray, board: Board, pb: PrintedBoard):
    """Grey value (0..255) and coverage of a :class:`PrintedBoard` at board coordinates (metres)."""
    u, v = bx / board.square, by / board.square
    wu = np.where(ok, _footprint(u), 1.0)
    wv = np.where(ok, _footprint(v), 1.0)
    lo, hi_u, hi_v = -pb.outer, board.cols - 1 + pb.outer, board.rows - 1 + pb.outer
    sq = _filtered_square_wave(u, wu) * _filtered_square_wave(v, wv)
    in_u = np.clip(0.5 + np.minimum(u - lo, hi_u - u) / np.maximum(wu, 1e-12), 0.0, 1.0)
    in_v = np.clip(0.5 + np.minimum(v - lo, hi_v - v) / np.maximum(wv, 1e-12), 0.0, 1.0)
    black = in_u * in_v * 0.5 * (1.0 + sq)
    # distance outside the squares' rectangle, in squares (negative inside)
    d = np.maximum(np.maximum(lo - u, u - hi_u), np.maximum(lo - v, v - hi_v))
    w = np.maximum(np.maximum(wu, wv), 1e-12)
    if pb.outline is not None:
        gap, thick = pb.outline
        band = np.clip(0.5 + (d - gap) / w, 0.0, 1.0) * np.clip(0.5 + (gap + thick - d) / w, 0.0, 1.0)
        black = np.maximum(black, band)
    cover = np.where(ok, np.clip(0.5 + (pb.margin - d) / w, 0.0, 1.0), 0.0).astype(np.float32)
    val = (255.0 * (pb.paper + (pb.ink - pb.paper) * black)).astype(np.float32)
    return val, cover


def _stress_background(rng: np.random.Generator, size: tuple[int, int], busy: bool) -> np.ndarray:
    """A dark wall (the board's edge is a strong edge), or with ``busy`` high-contrast boxes and bars."""
    w, h = size
    bg = np.full((h, w), 40.0, dtype=np.float32)
    if busy:
        for _ in range(260):
            x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
            bw, bh = int(rng.integers(3, 40)), int(rng.integers(3, 40))
            bg[y:y + bh, x:x + bw] = float(rng.choice([15.0, 90.0, 200.0]))
    return np.repeat(bg[:, :, None], 3, axis=2)


def _stress_setup(kind: str, rng: np.random.Generator):
    """(pose params (u, v, z, pitch, yaw, roll), PrintedBoard, Exposure, blur, busy background)."""
    cx, cy = dt.IMAGE_SIZE[0] / 2, dt.IMAGE_SIZE[1] / 2
    p = [cx + rng.uniform(-50, 50), cy + rng.uniform(-40, 40), rng.uniform(0.32, 0.42),
         rng.uniform(-25, 25), rng.uniform(-25, 25), rng.uniform(-20, 20)]
    pb, ex, blur, busy = PrintedBoard(), Exposure(vignetting=0.0), None, False
    if kind == "narrow_outer":
        pb = PrintedBoard(outer=float(rng.uniform(0.35, 0.45)), margin=float(rng.uniform(0.08, 0.15)))
    elif kind == "thick_outline":
        pb = PrintedBoard(outer=float(rng.uniform(0.5, 1.0)), margin=0.9,
                          outline=(float(rng.uniform(0.1, 0.25)), float(rng.uniform(0.15, 0.3))))
    elif kind == "edge_clutter":
        pb = PrintedBoard(outer=float(rng.uniform(0.4, 0.6)), margin=float(rng.uniform(0.1, 0.2)))
        busy = True
    elif kind == "perspective":
        p[3 if rng.random() < 0.5 else 4] = float(rng.choice([-1, 1]) * rng.uniform(52, 60))
        p[2] = rng.uniform(0.28, 0.34)
    elif kind == "distortion":
        p[0] = cx + rng.choice([-1, 1]) * rng.uniform(150, 170)
        p[1] = cy + rng.choice([-1, 1]) * rng.uniform(95, 110)
        p[2] = rng.uniform(0.36, 0.42)
    elif kind == "blur":
        ex = Exposure(vignetting=0.0, lens_blur=float(rng.uniform(1.2, 1.6)))
        a = rng.uniform(0, np.pi)
        blur = (2.0 * math.cos(a), 2.0 * math.sin(a))
    elif kind == "noise":
        ex = Exposure(vignetting=0.0, gain=float(rng.uniform(5.0, 7.0)))
    elif kind == "low_contrast":
        pb = PrintedBoard(paper=0.55, ink=0.22)
        ex = Exposure(vignetting=0.0, brightness=1.0)
    elif kind == "small_far":
        p[2] = rng.uniform(0.75, 0.9)
        p[0], p[1] = cx + rng.uniform(-150, 150), cy + rng.uniform(-100, 100)
    return p, pb, ex, blur, busy


def render_stress_case(kind: str, seed: int = 0, *, board: Board = DUCKIETOWN_BOARD,
                       renderer: Renderer | None = None) -> StressCase:
    """Render one frame of the detector's stress set, with exact corner truth.

    Kinds (:data:`STRESS_KINDS`): ``narrow_outer`` (outermost squares cut to 35-45 % and the
    board's edge right after them, on a dark wall), ``thick_outline`` (a printed black frame
    close to the squares), ``edge_clutter`` (cut squares, a thin margin, high-contrast clutter
    behind), ``perspective`` (tilted 52-60 degrees), ``distortion`` (a stronger barrel lens,
    board near an image corner), ``blur`` (lens and motion blur), ``noise`` (high gain),
    ``low_contrast`` (grey print on grey paper: 40 % of the usual contrast), ``small_far`` (squares of 10-12 px).
    Each ``seed`` draws another pose and print; the pose is redrawn until the whole board is
    in the picture.

    Parameters
    ----------
    kind : one of :data:`STRESS_KINDS`
    seed : random seed
    board : checkerboard (inner corners, square size)
    renderer : a :func:`make_renderer` of :func:`stress_camera` ``(kind)`` to reuse (built if None)

    Returns
    -------
    StressCase
    """
    if kind not in STRESS_KINDS:
        raise DtscalError(f"unknown stress case {kind!r}; choose one of {', '.join(STRESS_KINDS)}")
    camera = stress_camera(kind)
    if renderer is None or not (np.array_equal(renderer.camera.K, camera.K)
                                and np.array_equal(renderer.camera.dist, camera.dist)):
        renderer = make_renderer(camera)
    camera = renderer.camera
    rng = np.random.default_rng([STRESS_KINDS.index(kind), int(seed)])
    for _ in range(100):
        p, pb, ex, blur, busy = _stress_setup(kind, rng)
        R, t = _pose_from_params(camera, board, p)
        corners, visible = true_corners(camera, board, R, t)
        if visible:
            break
    else:  # pragma: no cover - the setups above are chosen to fit the image
        raise DtscalError(f"could not place a fully visible board for stress case {kind!r}, seed {seed}")
    background = _stress_background(rng, camera.size, busy)
    s = board.square
    ext = pb.outer + pb.margin
    corners_m = np.array([[-ext, -ext], [board.cols - 1 + ext, -ext], [board.cols - 1 + ext, board.rows - 1 + ext],
                          [-ext, board.rows - 1 + ext]]) * s
    bbox = _bbox(camera, R, t, np.column_stack([corners_m, np.zeros(4)]), pad=6)
    color, alpha = _render_layer(renderer, R, t, lambda a, b, ok: _printed_texture(a, b, ok, board, pb), bbox)
    kernel = _line_kernel(blur)
    if kernel is not None:
        color = cv2.filter2D(color, -1, kernel, borderType=cv2.BORDER_CONSTANT)
        alpha = cv2.filter2D(alpha, -1, kernel, borderType=cv2.BORDER_CONSTANT)
    linear = color + (1.0 - alpha)[:, :, None] * background
    image = _finish(linear.astype(np.float32), ex, rng)
    return StressCase(kind, int(seed), image, corners, bool(visible), board, camera, _rvec(R), t)
