"""Figures and small interactive views for the course notebooks (01 and 02).

Every figure function returns a :class:`matplotlib.figure.Figure` built without pyplot
(no global figure state; a notebook shows it by leaving it as the cell's last value) at a
small resolution (:data:`DPI`), so stored notebooks stay small.

Functions that run a student's function take it as an argument and fall back to the
library (with a printed message) while it is not written yet, so every notebook runs top
to bottom from the first day.
"""

from __future__ import annotations

import io
from typing import Callable, Sequence

import cv2
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .boards import DUCKIETOWN_BOARD, Board
from .camera import as_K, as_rotation, project_points as library_project_points, undistort_pixels
from .duckietown import IMAGE_SIZE
from .errors import DtscalError
from .selfcheck.projection import use_or_fallback

#: resolution of the stored figures (dots per inch)
DPI = 80
BOARD_COLOR, TRUTH_COLOR, OTHER_COLOR = "tab:orange", "tab:blue", "tab:green"


class CourseFigure(Figure):
    """A matplotlib Figure that shows itself as a PNG in a notebook (no pyplot needed)."""

    def _repr_png_(self) -> bytes:
        buf = io.BytesIO()
        self.savefig(buf, format="png", dpi=self.dpi, metadata={"Software": None})
        return buf.getvalue()


def _figure(width_in: float, height_in: float, dpi: int = DPI) -> Figure:
    fig = CourseFigure(figsize=(width_in, height_in), dpi=dpi, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def image_axes(ax, size: tuple[int, int] = IMAGE_SIZE, title: str = "") -> None:
    """Set an axes up as an image of ``size`` (width, height): pixel units, v pointing down."""
    w, h = size
    ax.set_xlim(-0.5, w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)
    ax.set_aspect("equal")
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")
    if title:
        ax.set_title(title, fontsize=10)


def draw_board(ax, uv: np.ndarray, board: Board = DUCKIETOWN_BOARD, color: str = BOARD_COLOR,
               label: str | None = None, marker: str = "o") -> None:
    """Draw projected inner corners (N, 2) as the board's grid: rows, columns, first corner marked."""
    uv = np.asarray(uv, dtype=float).reshape(board.rows, board.cols, 2)
    for r in range(board.rows):
        ax.plot(uv[r, :, 0], uv[r, :, 1], "-", color=color, lw=1)
    for c in range(board.cols):
        ax.plot(uv[:, c, 0], uv[:, c, 1], "-", color=color, lw=1)
    ax.plot(uv[..., 0].ravel(), uv[..., 1].ravel(), marker, color=color, ms=3, ls="none", label=label)
    ax.plot(uv[0, 0, 0], uv[0, 0, 1], "s", color="k", ms=5)


# --------------------------------------------------------------------------- notebook 01
def look_at_pose(yaw_deg: float = 0.0, pitch_deg: float = 0.0, roll_deg: float = 0.0,
                 distance: float = 0.5, shift_x: float = 0.0, shift_y: float = 0.0,
                 board: Board = DUCKIETOWN_BOARD) -> tuple[np.ndarray, np.ndarray]:
    """A camera looking at the board's centre: world (board) -> camera rotation (3, 3) and translation (3,).

    The camera starts ``distance`` metres in front of the board's centre, looking at it
    straight on, then turns by yaw (about its y axis), pitch (x axis) and roll (z axis),
    and is shifted sideways by ``shift_x``, ``shift_y`` metres in the board plane.
    """
    if not distance > 0:
        raise DtscalError(f"distance must be positive (metres in front of the board), got {distance}")
    y, p, r = np.deg2rad([yaw_deg, pitch_deg, roll_deg])
    Ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    Rx = np.array([[1, 0, 0], [0, np.cos(p), -np.sin(p)], [0, np.sin(p), np.cos(p)]])
    Rz = np.array([[np.cos(r), -np.sin(r), 0], [np.sin(r), np.cos(r), 0], [0, 0, 1]])
    R = Rz @ Rx @ Ry
    centre = board.object_points().mean(axis=0) + [shift_x, shift_y, 0.0]
    # the camera sits on the board normal through `centre`, at `distance`, then rotates about itself
    t = np.array([0.0, 0.0, distance]) - R @ centre
    return R, t


def _project_or_fallback(project_fn: Callable, K, R, t, X, quiet: bool = False) -> np.ndarray:
    if quiet:
        try:
            return np.asarray(project_fn(K, R, t, X), dtype=float)
        except Exception:
            return library_project_points(X, R, t, K)
    return np.asarray(use_or_fallback(
        project_fn, lambda K_, R_, t_, X_: library_project_points(X_, R_, t_, K_), K, R, t, X,
        what="the library's camera.project_points"), dtype=float)


def projection_figure(project_fn: Callable, K: np.ndarray, poses: Sequence[tuple], titles: Sequence[str],
                      board: Board = DUCKIETOWN_BOARD, size: tuple[int, int] = IMAGE_SIZE) -> Figure:
    """The board projected by ``project_fn(K, R, t, X)`` for several poses, one panel each.

    Parameters
    ----------
    project_fn : the student's ``project_points(K, R, t, X) -> (N, 2)``
    K : (3, 3) intrinsic matrix, or a list of them (one per pose)
    poses : list of (R (3, 3), t (3,)) board -> camera
    titles : one per pose
    """
    Ks = [as_K(k) for k in K] if np.ndim(K) == 3 else [as_K(K)] * len(poses)
    fig = _figure(2.3 * len(poses), 2.1)
    axes = fig.subplots(1, len(poses), squeeze=False)[0]
    X = board.object_points()
    for i, (ax, (R, t), k, title) in enumerate(zip(axes, poses, Ks, titles)):
        uv = _project_or_fallback(project_fn, k, R, t, X, quiet=i > 0)
        image_axes(ax, size, title)
        draw_board(ax, uv, board)
        ax.plot(k[0, 2], k[1, 2], "+", color="k", ms=8)
    return fig


class _Explorer:
    """State of :func:`pinhole_explorer`: the sliders, the image widget and the student's function."""

    def __init__(self, project_fn, K, board, size, widgets):
        self.project_fn, self.board, self.size = project_fn, board, size
        K = as_K(K)
        fs = dict(continuous_update=False, style={"description_width": "70px"},
                  layout=widgets.Layout(width="300px"))
        self.sliders = {
            "f": widgets.FloatSlider(value=float(K[0, 0]), min=100, max=800, step=10, description="f (px)", **fs),
            "cx": widgets.FloatSlider(value=float(K[0, 2]), min=0, max=size[0], step=5, description="cx (px)", **fs),
            "cy": widgets.FloatSlider(value=float(K[1, 2]), min=0, max=size[1], step=5, description="cy (px)", **fs),
            "skew": widgets.FloatSlider(value=float(K[0, 1]), min=-200, max=200, step=10, description="skew s", **fs),
            "distance": widgets.FloatSlider(value=0.5, min=0.15, max=2.0, step=0.05, description="distance (m)", **fs),
            "yaw": widgets.FloatSlider(value=0.0, min=-60, max=60, step=2, description="yaw (deg)", **fs),
            "pitch": widgets.FloatSlider(value=0.0, min=-60, max=60, step=2, description="pitch (deg)", **fs),
            "roll": widgets.FloatSlider(value=0.0, min=-180, max=180, step=5, description="roll (deg)", **fs),
            "shift_x": widgets.FloatSlider(value=0.0, min=-0.3, max=0.3, step=0.01, description="shift x (m)", **fs),
            "shift_y": widgets.FloatSlider(value=0.0, min=-0.3, max=0.3, step=0.01, description="shift y (m)", **fs),
        }
        self.image = widgets.Image(format="png", layout=widgets.Layout(width="400px"))
        self.status = widgets.HTML()
        for s in self.sliders.values():
            s.observe(lambda _change: self.redraw(), names="value")

    def camera(self):
        v = {k: s.value for k, s in self.sliders.items()}
        K = np.array([[v["f"], v["skew"], v["cx"]], [0.0, v["f"], v["cy"]], [0.0, 0.0, 1.0]])
        R, t = look_at_pose(v["yaw"], v["pitch"], v["roll"], v["distance"], v["shift_x"], v["shift_y"], self.board)
        return K, R, t

    def render(self) -> tuple[bytes, str]:
        K, R, t = self.camera()
        X = self.board.object_points()
        Xc = X @ R.T + t
        fig = _figure(4.0, 3.0, dpi=60)
        ax = fig.add_subplot()
        image_axes(ax, self.size, "what the camera sees")
        if np.any(Xc[:, 2] <= 1e-6):
            msg = "part of the board is behind the camera: turn back or move away"
        else:
            try:
                uv, msg = np.asarray(self.project_fn(K, R, t, X), dtype=float), "drawn with your project_points"
                if uv.shape != (len(X), 2) or not np.all(np.isfinite(uv)):
                    raise ValueError(f"result of shape {uv.shape} (or with NaN); expected ({len(X)}, 2)")
            except NotImplementedError:
                uv, msg = library_project_points(X, R, t, K), ("project_points is not written yet: using the "
                                                               "library's camera.project_points until it works")
            except Exception as exc:
                uv, msg = library_project_points(X, R, t, K), (f"your project_points raised {type(exc).__name__}: "
                                                               f"{exc}; showing the library's projection")
            draw_board(ax, uv, self.board)
            ax.plot(K[0, 2], K[1, 2], "+", color="k", ms=8)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=60, metadata={"Software": None})
        return buf.getvalue(), msg

    def redraw(self) -> None:
        png, msg = self.render()
        self.image.value = png
        self.status.value = f"<b>{msg}</b>"


def pinhole_explorer(project_fn: Callable, K: np.ndarray | None = None, board: Board = DUCKIETOWN_BOARD,
                     size: tuple[int, int] = IMAGE_SIZE):
    """Sliders for the camera pose and K; the board drawn with the student's ``project_fn``.

    Needs a running kernel (ipywidgets). The picture is a small PNG, so the widget adds
    little to a saved notebook; its text form (shown where widgets cannot render) says so.

    Returns
    -------
    ipywidgets.VBox
        Display it as a cell's last value.
    """
    import ipywidgets as widgets

    class ExplorerBox(widgets.VBox):
        def __repr__(self) -> str:
            return "pinhole explorer: sliders for K and the camera pose (needs a running Jupyter kernel)"

    K = np.array([[300.0, 0.0, size[0] / 2], [0.0, 300.0, size[1] / 2], [0.0, 0.0, 1.0]]) if K is None else K
    state = _Explorer(project_fn, K, board, size, widgets)
    state.redraw()
    s = state.sliders
    left = widgets.VBox([widgets.HTML("<b>intrinsics K</b>"), s["f"], s["cx"], s["cy"], s["skew"],
                         widgets.HTML("<b>camera pose</b>"), s["distance"], s["yaw"], s["pitch"], s["roll"],
                         s["shift_x"], s["shift_y"]])
    box = ExplorerBox([widgets.HBox([left, state.image]), state.status])
    box.explorer = state  # for tests and curious students
    return box


# --------------------------------------------------------------------------- notebook 02
def render_board_image(K: np.ndarray, dist, R, t, board: Board = DUCKIETOWN_BOARD,
                       size: tuple[int, int] = IMAGE_SIZE, supersample: int = 2,
                       background: int = 90) -> np.ndarray:
    """A grey image of the checkerboard seen by a (distorted) camera, by ray casting.

    Each pixel (supersampled ``supersample`` x ``supersample``) is undistorted, its ray is
    intersected with the board plane, and coloured by the square it hits. The board has
    ``cols + 1`` by ``rows + 1`` squares (inner corners at the object points) and a white
    margin of one square.

    Returns
    -------
    (height, width) uint8
    """
    w, h = size
    s = int(supersample)
    u, v = np.meshgrid((np.arange(w * s) + 0.5) / s - 0.5, (np.arange(h * s) + 0.5) / s - 0.5)
    xy = undistort_pixels(np.column_stack([u.ravel(), v.ravel()]), K, dist)
    rays = np.column_stack([xy, np.ones(len(xy))])
    R = as_rotation(R)
    t = np.asarray(t, dtype=float).reshape(3)
    n = R[:, 2]  # board normal in the camera frame; the plane holds the points with n . Xc = n . t
    denom = rays @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = (n @ t) / denom
    hit = np.isfinite(lam) & (lam > 0)
    Xb = (lam[:, None] * rays - t) @ R  # board-frame coordinates, rows R^T (Xc - t)
    sq = board.square
    i = np.floor(Xb[:, 0] / sq).astype(np.int64) + 1  # square column, 0 .. cols
    j = np.floor(Xb[:, 1] / sq).astype(np.int64) + 1
    inside = hit & (i >= 0) & (i <= board.cols) & (j >= 0) & (j <= board.rows)
    margin = hit & (i >= -1) & (i <= board.cols + 1) & (j >= -1) & (j <= board.rows + 1)
    img = np.full(len(xy), float(background))
    img[margin] = 235.0
    img[inside & ((i + j) % 2 == 0)] = 20.0
    img = img.reshape(h * s, w * s)
    return cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA).round().astype(np.uint8)


def fronto_parallel_view(image: np.ndarray, H_board_to_image: np.ndarray, board: Board = DUCKIETOWN_BOARD,
                         px_per_square: int = 40, margin_squares: float = 1.5) -> np.ndarray:
    """Warp an image so the board looks straight on: ``px_per_square`` pixels per square.

    ``H_board_to_image`` maps board coordinates (metres, (N, 2)) to image pixels. The
    output pixel ``(U, V)`` shows board point ``((U / s) - m, (V / s) - m)`` squares,
    ``m = margin_squares``.
    """
    sq, s, m = board.square, float(px_per_square), float(margin_squares)
    out_w = int(round(((board.cols - 1) + 2 * m) * s))
    out_h = int(round(((board.rows - 1) + 2 * m) * s))
    # output pixel -> board metres -> image pixel
    A = np.array([[sq / s, 0.0, -m * sq], [0.0, sq / s, -m * sq], [0.0, 0.0, 1.0]])
    M = np.asarray(H_board_to_image, dtype=float) @ A
    return cv2.warpPerspective(image, M, (out_w, out_h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                               borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def warp_figure(image: np.ndarray, corners: np.ndarray, warped: np.ndarray, board: Board = DUCKIETOWN_BOARD,
                px_per_square: int = 40, margin_squares: float = 1.5) -> Figure:
    """Left: the frame with its detected corners; right: the fronto-parallel view with the ideal grid."""
    fig = _figure(8.5, 3.2, dpi=64)
    a, b = fig.subplots(1, 2, width_ratios=[image.shape[1] / image.shape[0], warped.shape[1] / warped.shape[0]])
    a.imshow(image, cmap="gray", vmin=0, vmax=255)
    draw_board(a, corners, board)
    image_axes(a, (image.shape[1], image.shape[0]), "recorded frame and detected corners")
    b.imshow(warped, cmap="gray", vmin=0, vmax=255)
    s, m = px_per_square, margin_squares
    ideal = (board.object_points()[:, :2] / board.square + m) * s
    draw_board(b, ideal, board, color=TRUTH_COLOR)
    image_axes(b, (warped.shape[1], warped.shape[0]), "warped with inv(H): fronto-parallel")
    return fig


def unnormalized_dlt(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """The DLT **without** normalization, for the conditioning experiment only (do not use it).

    Builds the 2N x 9 system of eq. (6) cross-multiplied on the raw coordinates and
    takes the singular vector of the smallest singular value. Returns (3, 3), H[2, 2] = 1.
    """
    src = np.asarray(src, dtype=float).reshape(-1, 2)
    dst = np.asarray(dst, dtype=float).reshape(-1, 2)
    x, y, u, v = src[:, 0], src[:, 1], dst[:, 0], dst[:, 1]
    one, zero = np.ones_like(x), np.zeros_like(x)
    rows_u = np.stack([x, y, one, zero, zero, zero, -u * x, -u * y, -u], axis=1)
    rows_v = np.stack([zero, zero, zero, x, y, one, -v * x, -v * y, -v], axis=1)
    h = np.linalg.svd(np.vstack([rows_u, rows_v]))[2][-1]
    return h.reshape(3, 3) / h[8]


def _transfer(H, src, dst) -> float:
    p = np.column_stack([src, np.ones(len(src))]) @ np.asarray(H, float).T
    return float(np.sqrt(np.mean(np.sum((p[:, :2] / p[:, 2:3] - dst) ** 2, axis=1))))


def conditioning_experiment(estimate_fn: Callable, offsets: Sequence[float], sigma: float = 0.0,
                            n_points: int = 35, seed: int = 0) -> dict[str, np.ndarray]:
    """Transfer error of a homography fit as the source coordinates move away from the origin.

    For each offset the same pixel->pixel mapping is sampled with source points spread
    over a 640 x 480 area shifted by ``offset`` in x and y (destination noise ``sigma``
    pixels); it is fitted by ``estimate_fn``, by :func:`unnormalized_dlt` and by
    ``cv2.findHomography`` (method 0). ``estimate_fn`` falls back to OpenCV while it is not
    written yet (printed once).

    Returns
    -------
    dict with ``offset``, ``yours``, ``unnormalized``, ``opencv`` (len(offsets),) RMS pixels
    """
    rng = np.random.default_rng(seed)
    base = np.column_stack([rng.uniform(0, 640, n_points), rng.uniform(0, 480, n_points)])
    H0 = np.array([[0.9, 0.12, 40.0], [-0.05, 1.1, 25.0], [2e-4, 4e-4, 1.0]])
    noise = rng.normal(0.0, sigma, size=(n_points, 2)) if sigma > 0 else np.zeros((n_points, 2))
    out = {k: [] for k in ("offset", "yours", "unnormalized", "opencv")}
    fallback = lambda s, d: cv2.findHomography(s, d, 0)[0]  # noqa: E731
    for i, off in enumerate(offsets):
        src = base + off
        p = np.column_stack([base, np.ones(n_points)]) @ H0.T
        dst = p[:, :2] / p[:, 2:3] + noise
        if i == 0:
            H = use_or_fallback(estimate_fn, fallback, src, dst, what="OpenCV's cv2.findHomography")
        else:
            try:
                H = estimate_fn(src, dst)
            except Exception:
                H = fallback(src, dst)
        out["offset"].append(off)
        out["yours"].append(_transfer(H, src, dst))
        out["unnormalized"].append(_transfer(unnormalized_dlt(src, dst), src, dst))
        out["opencv"].append(_transfer(fallback(src, dst), src, dst))
    return {k: np.asarray(v, dtype=float) for k, v in out.items()}


def conditioning_figure(results: dict, title: str = "noise-free points") -> Figure:
    """Log-log plot of :func:`conditioning_experiment` results: transfer error vs offset, per method."""
    fig = _figure(4.6, 3.0)
    ax = fig.add_subplot()
    off = np.maximum(results["offset"], 1.0)
    ax.loglog(off, np.maximum(results["unnormalized"], 1e-16), "o-", label="DLT without normalization")
    ax.loglog(off, np.maximum(results["yours"], 1e-16), "s-", label="your estimate_homography")
    ax.loglog(off, np.maximum(results["opencv"], 1e-16), "^--", label="cv2.findHomography", alpha=0.7)
    ax.set_xlabel("offset of the source coordinates (px)")
    ax.set_ylabel("RMS transfer error (px)")
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def residual_figure(src: np.ndarray, dst: np.ndarray, fits: dict[str, np.ndarray], scale: float = 50.0,
                    size: tuple[int, int] = IMAGE_SIZE) -> Figure:
    """Residual arrows ``H src - dst`` of several fits (name -> H), magnified ``scale`` times."""
    fig = _figure(4.2 * len(fits), 3.2)
    axes = fig.subplots(1, len(fits), squeeze=False)[0]
    for ax, (name, H) in zip(axes, fits.items()):
        p = np.column_stack([src, np.ones(len(src))]) @ np.asarray(H, float).T
        r = p[:, :2] / p[:, 2:3] - dst
        rms = float(np.sqrt(np.mean(np.sum(r ** 2, axis=1))))
        ax.plot(dst[:, 0], dst[:, 1], ".", color="k", ms=3)
        ax.quiver(dst[:, 0], dst[:, 1], r[:, 0], r[:, 1], angles="xy", scale_units="xy", scale=1 / scale,
                  color="tab:red", width=0.004)
        image_axes(ax, size, f"{name}: RMS {rms:.3f} px (arrows x{scale:g})")
    return fig
