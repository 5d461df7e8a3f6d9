"""Realistic test frames for the detection and calibration benchmarks (and the detector's tests).

A :class:`FrameRenderer` draws the Duckietown 7x5 board (8x6 squares of 31 mm with a
white margin) as the Duckiebot camera sees it: a pinhole pose, the camera's strong barrel
distortion (via :mod:`dtscal_lib.camera`), 2x supersampling for anti-aliasing, uneven
lighting, lens blur, sensor noise and JPEG compression. The inner corners' exact pixel
positions are returned with each frame (``camera.project_points`` of the board's object
points), so detections can be scored against ground truth.

:func:`clutter_image` draws board-free scenes that are hard for OpenCV's classic
chessboard detector: floor tiles, tape lines, boxes, shelves and noise give it many
quadrilaterals to try to assemble.

Nothing here is part of the library: it is measurement scaffolding.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import cv2
import numpy as np

from dtscal_lib import camera
from dtscal_lib import duckietown as dt
from dtscal_lib import poses, synth
from dtscal_lib.boards import DUCKIETOWN_BOARD, Board


# --------------------------------------------------------------------------- poses
def look_at_pose(board: Board, distance: float, tilt_x: float = 0.0, tilt_y: float = 0.0,
                 roll: float = 0.0, shift: tuple[float, float] = (0.0, 0.0)):
    """A board pose ``(rvec, tvec)`` (board -> camera) with the board centre in front of the camera.

    ``distance`` metres along the optical axis to the board centre, ``tilt_x``/``tilt_y``
    rotations (radians) of the board about its own horizontal/vertical axis, ``roll``
    about the optical axis, ``shift`` the board centre's (x, y) offset in metres: the
    library's :func:`dtscal_lib.poses.look_at_pose`, with the centre then moved sideways.
    """
    R, t = poses.look_at_pose(np.degrees(tilt_y), np.degrees(tilt_x), np.degrees(roll), distance, board=board)
    return cv2.Rodrigues(R)[0].ravel(), t + [shift[0], shift[1], 0.0]


def random_visible_pose(rng: np.random.Generator, board: Board = DUCKIETOWN_BOARD,
                        K=None, dist=None, size=dt.IMAGE_SIZE, margin: float = 20.0,
                        distance=(0.28, 0.75), max_tilt: float = 0.7, max_roll: float = 0.5,
                        tries: int = 200):
    """A random realistic pose whose whole board (with its white margin) is inside the image.

    Returns ``(rvec, tvec, corners)`` with ``corners`` the (N, 2) exact pixel positions.
    """
    K = dt.default_K() if K is None else K
    dist = dt.default_dist() if dist is None else dist
    w, h = size
    outline = _board_outline(board)
    for _ in range(tries):
        d = rng.uniform(*distance)
        r, t = look_at_pose(board, d, rng.uniform(-max_tilt, max_tilt), rng.uniform(-max_tilt, max_tilt),
                            rng.uniform(-max_roll, max_roll),
                            (rng.uniform(-0.45, 0.45) * d, rng.uniform(-0.35, 0.35) * d))
        try:
            out = camera.project_points(outline, r, t, K, dist)
        except Exception:
            continue
        if out[:, 0].min() < margin or out[:, 1].min() < margin or out[:, 0].max() > w - margin \
                or out[:, 1].max() > h - margin:
            continue
        # the strong barrel model folds back far off-axis; reject poses near that region
        xy = camera.undistort_pixels(out, K, dist)
        if np.abs(xy).max() > 1.1:
            continue
        return r, t, camera.project_points(board.object_points(), r, t, K, dist)
    raise RuntimeError("no visible pose found; loosen the pose ranges")


def _board_outline(board: Board, n: int = 12) -> np.ndarray:
    """Points along the printed board's outer edge (one square outside the inner corners)."""
    s = board.square
    x0, x1 = -s * 1.5, (board.cols + 0.5) * s
    y0, y1 = -s * 1.5, (board.rows + 0.5) * s
    a = np.linspace(0, 1, n)
    pts = [np.column_stack([x0 + (x1 - x0) * a, np.full(n, y)]) for y in (y0, y1)]
    pts += [np.column_stack([np.full(n, x), y0 + (y1 - y0) * a]) for x in (x0, x1)]
    p = np.vstack(pts)
    return np.column_stack([p, np.zeros(len(p))])


# --------------------------------------------------------------------------- rendering
@dataclass
class RenderedFrame:
    image: np.ndarray          # (h, w, 3) uint8 BGR (after JPEG round trip)
    corners: np.ndarray | None  # (N, 2) float64 exact inner-corner pixels, board row-major order
    rvec: np.ndarray | None
    tvec: np.ndarray | None


class FrameRenderer:
    """Renders Duckiebot-camera frames of a checkerboard with exact ground truth.

    The per-pixel undistortion of the (supersampled) image grid is computed once (the kit's
    ray caster, :class:`dtscal_lib.synth.Renderer`), so each frame costs only casting the rays
    onto the board plane, two ``remap`` calls of a printed-board texture and the photometric effects.
    """

    def __init__(self, board: Board = DUCKIETOWN_BOARD, K=None, dist=None,
                 size: tuple[int, int] = dt.IMAGE_SIZE, supersample: int = 2, px_per_square: int = 48):
        self.board = board
        self.K = dt.default_K() if K is None else np.asarray(K, float)
        self.dist = dt.default_dist() if dist is None else camera.as_dist(dist)
        self.size = (int(size[0]), int(size[1]))
        self.ss = int(supersample)
        # the kit's ray caster: one undistorted ray per sub-pixel, cast onto the board plane per frame
        self._caster = synth.make_renderer(camera.CameraModel(self.K, self.dist, self.size), self.ss)
        # texture: (cols+1) x (rows+1) squares plus a one-square white margin
        self.pps = int(px_per_square)
        nx, ny = board.cols + 1, board.rows + 1
        tex = np.full(((ny + 2) * self.pps, (nx + 2) * self.pps), 255, np.uint8)
        for j in range(ny):
            for i in range(nx):
                if (i + j) % 2 == 0:
                    tex[(j + 1) * self.pps:(j + 2) * self.pps, (i + 1) * self.pps:(i + 2) * self.pps] = 0
        self.texture = tex

    def _board_to_texture_px(self, bxy: np.ndarray) -> np.ndarray:
        # inner corner (0, 0) sits two squares in from the texture's edge (margin + first square)
        return bxy / self.board.square * self.pps + 2 * self.pps - 0.5

    def render(self, rvec, tvec, background: np.ndarray, rng: np.random.Generator, *,
               blur: float = 0.8, noise: float = 3.0, jpeg_quality: int = 85,
               contrast: float = 0.75, light_gradient: float = 0.35) -> RenderedFrame:
        """Render the board at pose ``(rvec, tvec)`` over a BGR ``background`` (h, w, 3) uint8."""
        R = camera.as_rotation(rvec)
        t = np.asarray(tvec, float).reshape(3)
        bx, by, front = self._caster.plane_coords(R, t)
        bxy = np.stack([bx, by], axis=-1)
        bxy[~front] = -1e6
        tex_px = self._board_to_texture_px(bxy).astype(np.float32)
        mx, my = np.ascontiguousarray(tex_px[..., 0]), np.ascontiguousarray(tex_px[..., 1])
        board_img = cv2.remap(self.texture, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                              borderValue=0)
        alpha = cv2.remap(np.full_like(self.texture, 255), mx, my, cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        w, h = self.size
        board_img = cv2.resize(board_img, (w, h), interpolation=cv2.INTER_AREA).astype(np.float32)
        alpha = cv2.resize(alpha, (w, h), interpolation=cv2.INTER_AREA).astype(np.float32)[..., None] / 255.0
        # paper is not perfectly black/white: map 0..255 to a reduced range
        lo = 128 - 127 * contrast
        board_rgb = (lo + board_img * contrast)[..., None] * np.array([1.0, 0.98, 0.95], np.float32)
        img = background.astype(np.float32) * (1 - alpha) + board_rgb * alpha
        img = _photometric(img, rng, blur=blur, noise=noise, light_gradient=light_gradient)
        img = _jpeg(img, jpeg_quality)
        corners = camera.project_points(self.board.object_points(), R, t, self.K, self.dist)
        return RenderedFrame(img, corners, np.asarray(rvec, float).ravel(), t)

    def render_empty(self, background: np.ndarray, rng: np.random.Generator, *, blur: float = 0.8,
                     noise: float = 3.0, jpeg_quality: int = 85) -> RenderedFrame:
        """The same camera effects on a frame with no board."""
        img = _photometric(background.astype(np.float32), rng, blur=blur, noise=noise, light_gradient=0.35)
        return RenderedFrame(_jpeg(img, jpeg_quality), None, None, None)


def _photometric(img: np.ndarray, rng: np.random.Generator, *, blur: float, noise: float,
                 light_gradient: float) -> np.ndarray:
    h, w = img.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    ang = rng.uniform(0, 2 * np.pi)
    g = ((xx - w / 2) * np.cos(ang) + (yy - h / 2) * np.sin(ang)) / max(w, h)
    vign = 1 - 0.35 * (((xx - w / 2) / w) ** 2 + ((yy - h / 2) / h) ** 2) * 2
    img = img * ((1 + light_gradient * g) * vign)[..., None]
    if blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    if noise > 0:
        img = img + rng.normal(0, noise, img.shape).astype(np.float32)
    return np.clip(img, 0, 255).astype(np.uint8)


def _jpeg(img: np.ndarray, quality: int) -> np.ndarray:
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    assert ok
    return cv2.imdecode(buf, cv2.IMREAD_COLOR)


# --------------------------------------------------------------------------- clutter
def clutter_image(rng: np.random.Generator, size: tuple[int, int] = dt.IMAGE_SIZE,
                  kind: str = "mixed") -> np.ndarray:
    """A board-free BGR scene (h, w, 3) uint8 that is hard for a chessboard detector.

    ``kind``: ``"tiles"`` (a perspective floor of dark/light tiles with tape lines: many
    quads), ``"rects"`` (hundreds of random filled rectangles), ``"office"`` (walls,
    shelves, boxes, a window grid, a table edge: a natural-looking indoor scene),
    ``"noise"`` (textured noise and gradients) or ``"mixed"`` (office over tiles).
    """
    w, h = size
    if kind == "tiles":
        return _tiles(rng, w, h)
    if kind == "rects":
        img = _gradient(rng, w, h)
        for _ in range(400):
            x, y = rng.integers(0, w), rng.integers(0, h)
            rw, rh = rng.integers(4, 40), rng.integers(4, 40)
            cv2.rectangle(img, (int(x), int(y)), (int(x + rw), int(y + rh)), _color(rng), -1)
        return img
    if kind == "office":
        return _office(rng, w, h, _gradient(rng, w, h))
    if kind == "noise":
        img = _gradient(rng, w, h).astype(np.float32)
        small = rng.uniform(0, 255, (h // 8, w // 8, 3)).astype(np.float32)
        img = 0.5 * img + 0.5 * cv2.resize(small, (w, h), interpolation=cv2.INTER_NEAREST)
        return np.clip(img, 0, 255).astype(np.uint8)
    if kind == "mixed":
        return _office(rng, w, h, _tiles(rng, w, h))
    raise ValueError(f"unknown clutter kind {kind!r}")


def _color(rng) -> tuple[int, int, int]:
    v = int(rng.integers(0, 256))
    tint = rng.integers(-30, 31, 3)
    return tuple(int(np.clip(v + c, 0, 255)) for c in tint)


def _gradient(rng, w, h) -> np.ndarray:
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    a, b, c = rng.uniform(60, 200), rng.uniform(-80, 80), rng.uniform(-80, 80)
    g = a + b * xx / w + c * yy / h
    return np.clip(np.repeat(g[..., None], 3, axis=2) * rng.uniform(0.85, 1.15, 3), 0, 255).astype(np.uint8)


def _tiles(rng, w, h) -> np.ndarray:
    """A floor of alternating tiles seen in perspective (Duckietown's mats look like this)."""
    n = int(rng.integers(10, 18))
    tile = 24
    tex = np.zeros((n * tile, n * tile, 3), np.uint8)
    for j in range(n):
        for i in range(n):
            base = 50 if (i + j) % 2 else 90
            tex[j * tile:(j + 1) * tile, i * tile:(i + 1) * tile] = base + rng.integers(-15, 16)
    # yellow dashes and white tape lines
    for k in range(0, n * tile, 3 * tile):
        cv2.line(tex, (k, 0), (k, n * tile), (240, 240, 240), 3)
        cv2.rectangle(tex, (0, k + 5), (n * tile, k + 9), (0, 210, 230), -1)
    src = np.float32([[0, 0], [n * tile, 0], [n * tile, n * tile], [0, n * tile]])
    hz = h * rng.uniform(0.25, 0.45)
    dst = np.float32([[w * 0.3, hz], [w * 0.7, hz], [w * 1.6, h * 1.2], [-w * 0.6, h * 1.2]])
    M = cv2.getPerspectiveTransform(src, dst)
    img = _gradient(rng, w, h)
    return cv2.warpPerspective(tex, M, (w, h), dst=img, borderMode=cv2.BORDER_TRANSPARENT)


def _office(rng, w, h, img) -> np.ndarray:
    img = img.copy()
    # a window with a grid of panes (quads in a grid: the classic detector's worst case)
    x0, y0 = int(rng.integers(0, w // 2)), int(rng.integers(0, h // 3))
    pw, ph = int(rng.integers(14, 30)), int(rng.integers(14, 30))
    for j in range(int(rng.integers(3, 6))):
        for i in range(int(rng.integers(3, 7))):
            c = int(rng.integers(180, 250))
            cv2.rectangle(img, (x0 + i * (pw + 4), y0 + j * (ph + 4)),
                          (x0 + i * (pw + 4) + pw, y0 + j * (ph + 4) + ph), (c, c, c - 10), -1)
    # shelves of boxes
    for _ in range(int(rng.integers(15, 40))):
        x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
        bw, bh = int(rng.integers(10, 70)), int(rng.integers(10, 60))
        cv2.rectangle(img, (x, y), (x + bw, y + bh), _color(rng), -1)
        cv2.rectangle(img, (x, y), (x + bw, y + bh), _color(rng), 1)
    # a duckie-ish blob, table edges and cables
    for _ in range(int(rng.integers(3, 8))):
        cv2.ellipse(img, (int(rng.integers(0, w)), int(rng.integers(0, h))),
                    (int(rng.integers(8, 30)), int(rng.integers(8, 30))), float(rng.uniform(0, 180)), 0, 360,
                    (0, int(rng.integers(180, 230)), int(rng.integers(220, 255))), -1)
    for _ in range(int(rng.integers(4, 12))):
        p1 = (int(rng.integers(0, w)), int(rng.integers(0, h)))
        p2 = (int(rng.integers(0, w)), int(rng.integers(0, h)))
        cv2.line(img, p1, p2, _color(rng), int(rng.integers(1, 5)))
    # a small checker-like sticker (wrong size: must not be found as a 7x5 board)
    sx, sy = int(rng.integers(0, w - 60)), int(rng.integers(0, h - 60))
    for j in range(4):
        for i in range(4):
            v = 20 if (i + j) % 2 == 0 else 235
            cv2.rectangle(img, (sx + i * 12, sy + j * 12), (sx + i * 12 + 11, sy + j * 12 + 11), (v, v, v), -1)
    return img


# --------------------------------------------------------------------------- timing
def median_time(fn, *args, repeats: int = 15, warmup: int = 2) -> float:
    """Median wall time of ``fn(*args)`` in seconds."""
    for _ in range(warmup):
        fn(*args)
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn(*args)
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))
