"""The kit's one figure convention: pyplot-free matplotlib figures that show themselves.

Used by the library's report (:mod:`dtscal_lib.report`) and by the teaching layer
(:mod:`dtscal_lib.teaching.course`, which re-exports it as ``dtscal_lib.teaching.course.figure``).

Every course figure is a :class:`CourseFigure` made by :func:`new_figure`: no pyplot, no
global ``rcParams``, no ``plt.show()``. A notebook shows a figure by leaving it as the cell's
last value; it is stored as a small PNG (:data:`DPI`, :data:`PHOTO_DPI`) so notebooks stay
small, and its text form (``<CourseFigure size ...>``) is the same on every machine.
"""

from __future__ import annotations

import io
from typing import Sequence

import cv2
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .boards import DUCKIETOWN_BOARD, Board
from .duckietown import IMAGE_SIZE

__all__ = ["CourseFigure", "new_figure", "image_axes", "draw_board", "show_image", "show_images", "png_bytes", "DPI",
           "PHOTO_DPI", "BOARD_COLOR", "TRUTH_COLOR", "OTHER_COLOR"]

#: resolution of plots (dots per inch)
DPI = 80
#: camera frames compress poorly as PNG: a lower resolution keeps notebooks small
PHOTO_DPI = 70
BOARD_COLOR, TRUTH_COLOR, OTHER_COLOR = "tab:orange", "tab:blue", "tab:green"
_FONT = {"font.size": 9, "axes.titlesize": 10}


class CourseFigure(Figure):
    """A matplotlib Figure that shows itself as a PNG in a notebook (no pyplot needed)."""

    def _repr_png_(self) -> bytes:
        return png_bytes(self)


def png_bytes(fig: Figure, dpi: float | None = None) -> bytes:
    """The figure as PNG bytes (no timestamp or software tag, so the bytes are reproducible)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi or fig.dpi, metadata={"Software": None})
    return buf.getvalue()


def new_figure(width_in: float, height_in: float, dpi: int = DPI) -> CourseFigure:
    """An empty :class:`CourseFigure` of ``width_in`` x ``height_in`` inches, constrained layout.

    >>> fig = new_figure(2.0, 1.0)
    >>> ax = fig.add_subplot()
    >>> png_bytes(fig)[:4] == b"\\x89PNG"
    True
    """
    import matplotlib as mpl

    with mpl.rc_context(_FONT):
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
        ax.set_title(title, fontsize=9)


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


def show_image(ax, image: np.ndarray, title: str = "") -> None:
    """Draw a BGR or grey uint8 image on ``ax``, titled, without axes."""
    if image.ndim == 2:
        ax.imshow(image, cmap="gray", vmin=0, vmax=255)
    else:
        ax.imshow(cv2.cvtColor(image, cv2.COLOR_BGR2RGB))
    if title:
        ax.set_title(title, fontsize=9)
    ax.axis("off")


def show_images(images: Sequence[np.ndarray], titles: Sequence[str], width: float = 4.2) -> CourseFigure:
    """Images (BGR or grey) side by side, titled."""
    fig = new_figure(width * len(images), width * 0.78, dpi=PHOTO_DPI)
    axes = fig.subplots(1, len(images), squeeze=False)[0]
    for ax, im, title in zip(axes, images, titles):
        show_image(ax, im, title)
    return fig
