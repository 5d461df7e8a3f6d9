"""Figures of the pinhole projection (activity text, eqs. (1)-(2)): camera poses, projected boards, the explorer."""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from ... import camera as cam
from ... import duckietown as dt
from ...boards import DUCKIETOWN_BOARD, Board
from ...duckietown import IMAGE_SIZE
from ...errors import DtscalError
from ...poses import look_at_pose, random_board_pose
from ...synth import make_renderer
from .fallback import Fallback
from .figure import CourseFigure, draw_board, image_axes, new_figure, png_bytes

__all__ = ["look_at_pose", "sample_views", "projection_figure", "pinhole_explorer", "render_board_image"]


def sample_views(K: np.ndarray, n: int, seed: int, *, min_tilt_deg: float = 10.0, max_tilt_deg: float = 40.0,
                 distance: tuple[float, float] = (0.3, 0.6), dist=None, size=dt.IMAGE_SIZE,
                 board: Board = DUCKIETOWN_BOARD) -> list[tuple[np.ndarray, np.ndarray]]:
    """Random board poses (R, t) in front of a camera with the whole board inside the image.

    The board is tilted by ``min_tilt_deg`` .. ``max_tilt_deg`` about a random axis in the
    image plane, ``distance`` metres away, and placed anywhere its corners stay inside the
    image by ROS's border margin. Deterministic for a given ``seed``.
    """
    rng = np.random.default_rng(seed)
    obj = board.object_points()
    w, h = size
    out: list = []
    tries = 0
    while len(out) < n:
        tries += 1
        if tries > 200 * n:
            raise DtscalError("could not place the board inside the image; widen the distance range")
        R, t = random_board_pose(rng, board, tilt_deg=(min_tilt_deg, max_tilt_deg), distance=distance,
                                 spread=(0.35, 0.25), spin_deg=20.0)
        try:
            uv = cam.project_points(obj, R, t, K, dist)
        except DtscalError:
            continue
        m = dt.BORDER_MARGIN_PX
        if np.all((uv[:, 0] > m) & (uv[:, 0] < w - m) & (uv[:, 1] > m) & (uv[:, 1] < h - m)):
            out.append((R, t))
    return out


def projection_figure(project: Callable, K: np.ndarray, poses: Sequence[tuple], titles: Sequence[str],
                      board: Board = DUCKIETOWN_BOARD, size: tuple[int, int] = IMAGE_SIZE) -> CourseFigure:
    """The board projected by ``project(K, R, t, X)`` for several poses, one panel each.

    Parameters
    ----------
    project : ``project_points(K, R, t, X) -> (N, 2)``, usually the notebook's
        :class:`~dtscal_lib.teaching.course.fallback.Fallback` (the student's function or the stand-in)
    K : (3, 3) intrinsic matrix, or a list of them (one per pose)
    poses : list of (R (3, 3), t (3,)) board -> camera
    titles : one per pose
    """
    Ks = [cam.as_K(k) for k in K] if np.ndim(K) == 3 else [cam.as_K(K)] * len(poses)
    cols = min(3, len(poses))  # legible panels: at most three side by side
    rows = -(-len(poses) // cols)
    fig = new_figure(3.0 * cols, 2.45 * rows)
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    for ax in axes[len(poses):]:
        ax.remove()
    X = board.object_points()
    for ax, (R, t), k, title in zip(axes, poses, Ks, titles):
        uv = np.asarray(project(k, R, t, X), dtype=float)
        image_axes(ax, size, title)
        draw_board(ax, uv, board)
        ax.plot(k[0, 2], k[1, 2], "+", color="k", ms=8)
    fig.alt = (f"The Duckietown board as the camera sees it, one image per panel ({len(poses)}): its 35 inner corners "
               "joined into rows and columns, corner 0 marked by a black square, the principal point by a cross.")
    return fig


#: the explorer's picture: rendered at the size it is shown (no stretching)
EXPLORER_PX = (400, 300)


class _Explorer:
    """State of :func:`pinhole_explorer`: the sliders, the image widget and the projection in use."""

    def __init__(self, project, K, board, size, widgets):
        self.project, self.board, self.size = project, board, size
        K = cam.as_K(K)
        fs = dict(continuous_update=False, style={"description_width": "95px"},
                  layout=widgets.Layout(width="330px"))
        self.sliders = {
            "f": widgets.FloatSlider(value=float(K[0, 0]), min=100, max=800, step=10, description="f (px)", **fs),
            "cx": widgets.FloatSlider(value=float(K[0, 2]), min=0, max=size[0], step=5, description="cx (px)", **fs),
            "cy": widgets.FloatSlider(value=float(K[1, 2]), min=0, max=size[1], step=5, description="cy (px)", **fs),
            "skew": widgets.FloatSlider(value=float(K[0, 1]), min=-200, max=200, step=10, description="skew s (px)",
                                        **fs),
            "distance": widgets.FloatSlider(value=0.5, min=0.15, max=2.0, step=0.05, description="distance (m)", **fs),
            "yaw": widgets.FloatSlider(value=0.0, min=-60, max=60, step=2, description="yaw (deg)", **fs),
            "pitch": widgets.FloatSlider(value=0.0, min=-60, max=60, step=2, description="pitch (deg)", **fs),
            "roll": widgets.FloatSlider(value=0.0, min=-180, max=180, step=5, description="roll (deg)", **fs),
            "shift_x": widgets.FloatSlider(value=0.0, min=-0.3, max=0.3, step=0.01, description="shift x (m)", **fs),
            "shift_y": widgets.FloatSlider(value=0.0, min=-0.3, max=0.3, step=0.01, description="shift y (m)", **fs),
        }
        w, h = EXPLORER_PX
        self.image = widgets.Image(format="png", layout=widgets.Layout(width=f"{w}px", height=f"{h}px"))
        self.status = widgets.HTML()
        for s in self.sliders.values():
            s.observe(lambda _change: self.redraw(), names="value")

    def camera(self):
        v = {k: s.value for k, s in self.sliders.items()}
        K = np.array([[v["f"], v["skew"], v["cx"]], [0.0, v["f"], v["cy"]], [0.0, 0.0, 1.0]])
        R, t = look_at_pose(v["yaw"], v["pitch"], v["roll"], v["distance"], v["shift_x"], v["shift_y"], self.board)
        return K, R, t

    def _drawn_with(self) -> str:
        if isinstance(self.project, Fallback):
            if self.project.last_fell_back and self.project.uses_student:
                return f"your {self.project.name} failed here: drawn with {self.project.fallback_name}"
            return f"drawn with {self.project.label}"
        return f"drawn with {getattr(self.project, '__name__', 'your function')}"

    def render(self) -> tuple[bytes, str]:
        K, R, t = self.camera()
        X = self.board.object_points()
        Xc = X @ R.T + t
        dpi = 100
        fig = new_figure(EXPLORER_PX[0] / dpi, EXPLORER_PX[1] / dpi, dpi=dpi)
        ax = fig.add_subplot()
        image_axes(ax, self.size, "what the camera sees")
        if np.any(Xc[:, 2] <= 1e-6):
            msg = "part of the board is behind the camera: turn back or move away"
        else:
            try:
                uv, msg = np.asarray(self.project(K, R, t, X), dtype=float), self._drawn_with()
                if uv.shape != (len(X), 2) or not np.all(np.isfinite(uv)):
                    raise ValueError(f"result of shape {uv.shape} (or with NaN); expected ({len(X)}, 2)")
            except Exception as exc:
                uv, msg = cam.project_points(X, R, t, K), (f"the projection raised {type(exc).__name__}: {exc}; "
                                                           "showing the library's camera.project_points")
            draw_board(ax, uv, self.board)
            ax.plot(K[0, 2], K[1, 2], "+", color="k", ms=8)
        return png_bytes(fig), msg

    def redraw(self) -> None:
        png, msg = self.render()
        self.image.value = png
        self.status.value = f"<b>{msg}</b>"


def pinhole_explorer(project: Callable, K: np.ndarray | None = None, board: Board = DUCKIETOWN_BOARD,
                     size: tuple[int, int] = IMAGE_SIZE):
    """Sliders for the camera pose and K; the board drawn with ``project(K, R, t, X)``.

    Needs a running kernel (ipywidgets). The picture is a small PNG rendered at the size it
    is shown; the widget's text form (shown where widgets cannot render) says what it is.

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
    state = _Explorer(project, K, board, size, widgets)
    state.redraw()
    s = state.sliders
    left = widgets.VBox([widgets.HTML("<b>intrinsics K</b>"), s["f"], s["cx"], s["cy"], s["skew"],
                         widgets.HTML("<b>camera pose</b>"), s["distance"], s["yaw"], s["pitch"], s["roll"],
                         s["shift_x"], s["shift_y"]])
    box = ExplorerBox([widgets.HBox([left, state.image]), state.status])
    box.explorer = state  # for tests and curious students
    return box


def render_board_image(K: np.ndarray, dist, R, t, board: Board = DUCKIETOWN_BOARD,
                       size: tuple[int, int] = IMAGE_SIZE, supersample: int = 2,
                       background: int = 90) -> np.ndarray:
    """A grey image of the checkerboard seen by a (distorted) camera, by ray casting.

    Each pixel (supersampled ``supersample`` x ``supersample``) is undistorted, its ray is
    intersected with the board plane, and coloured by the square it hits: the kit's ray
    caster, :class:`dtscal_lib.synth.Renderer`. The board has ``cols + 1`` by ``rows + 1``
    squares (inner corners at the object points) and a white margin of one square.

    Returns
    -------
    (height, width) uint8
    """
    renderer = make_renderer(cam.CameraModel(K, dist, size), supersample)
    bx, by, hit = renderer.plane_coords(R, t)
    sq = board.square
    i = np.floor(bx / sq).astype(np.int64) + 1  # square column, 0 .. cols
    j = np.floor(by / sq).astype(np.int64) + 1
    inside = hit & (i >= 0) & (i <= board.cols) & (j >= 0) & (j <= board.rows)
    margin = hit & (i >= -1) & (i <= board.cols + 1) & (j >= -1) & (j <= board.rows + 1)
    img = np.full(bx.shape, float(background))
    img[margin] = 235.0
    img[inside & ((i + j) % 2 == 0)] = 20.0
    return renderer.downsample(img).round().astype(np.uint8)
