"""The kit's one figure convention: pyplot-free matplotlib figures that show themselves.

Used by the library's report (:mod:`dtscal_lib.report`) and by the teaching layer
(:mod:`dtscal_lib.teaching.course`, which re-exports it as ``dtscal_lib.teaching.course.figure``).

Every course figure is a :class:`CourseFigure` made by :func:`new_figure`: no pyplot, no
global ``rcParams``, no ``plt.show()``. A notebook shows a figure by leaving it as the cell's
last value (or passing it to ``display``); it is stored as a small PNG (:data:`DPI`; a figure of
camera frames as JPEG at :data:`PHOTO_DPI`) so notebooks stay small. Its alt text is a sentence saying
what the figure shows (:attr:`CourseFigure.alt`, set by the function that draws it), followed by each
panel's title and axes (:func:`describe`); it is the same on every machine.

The figure is displayed as ``text/html``, an ``<img>`` whose ``alt`` attribute is that text, and as ``text/plain``
(the same text, for a terminal or a diff). Neither JupyterLab (4.6: its PNG renderer, ``renderImage`` in
``@jupyterlab/rendermime``, sets no ``alt``) nor nbconvert's default ``lab`` HTML template (its ``data_png`` block
writes no ``alt``; the ``classic`` one reads ``output.metadata['image/png']['alt']`` and otherwise writes "No
description has been provided for this image") can put an alt text on an ``image/png`` output; both prefer
``text/html`` to ``image/png`` and keep its ``alt`` (JupyterLab's sanitizer too, for an untrusted notebook;
``tests/test_figures_on_screen.py`` checks both in Chromium).

Colours come from :data:`PALETTE`, Okabe and Ito's colour-blind-safe set (Okabe & Ito, *Color Universal Design*,
2008, https://jfly.uni-koeln.de/color/): no red/green pair, distinguishable under deuteranopia and protanopia
(``tests/test_figure_palette.py`` checks it with Machado et al.'s 2009 simulation matrices). Every colour the kit
draws, in figures, on frames (:func:`bgr`), in the live tools and the HTML reports, is one of them or a grey
(:data:`GREY`); a verdict is :data:`GOOD_COLOR`, :data:`WARN_COLOR` or :data:`BAD_COLOR`.
"""

from __future__ import annotations

import base64
import html
import io
from typing import Sequence

import cv2
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .boards import DUCKIETOWN_BOARD, Board
from .duckietown import IMAGE_SIZE

__all__ = ["CourseFigure", "new_figure", "figure_html", "describe", "png_bytes", "image_axes", "draw_board",
           "show_image", "show_images", "bgr", "outlined", "DPI", "PHOTO_DPI", "PHOTO_MIN_PX", "PHOTO_PANEL_IN",
           "PALETTE", "GREY",
           "BOARD_COLOR", "TRUTH_COLOR", "OTHER_COLOR", "ARROW_COLOR", "GOOD_COLOR", "WARN_COLOR", "BAD_COLOR"]

#: resolution of plots (dots per inch)
DPI = 80
#: resolution of figures of camera frames, which a notebook stores as JPEG (:data:`PHOTO_JPEG_QUALITY`): frames
#: compress poorly as PNG (notebook 03's six frames: 500 kB as PNG, 99 kB as JPEG at quality 90)
PHOTO_DPI = 70
PHOTO_JPEG_QUALITY = 90
#: the narrowest a camera frame is drawn (px): a 640 px frame shown smaller than about half its size hides the
#: detail the text points at (corners, bent lines, labels); ``tests/test_figure_palette.py`` measures every panel
PHOTO_MIN_PX = 300
#: inches per photo panel that give PHOTO_MIN_PX at PHOTO_DPI once a title and the layout's pads are taken off
PHOTO_PANEL_IN = 4.8
#: Okabe-Ito's colour-blind-safe palette (black left out: the kit draws marks in black separately)
PALETTE = {"orange": "#E69F00", "sky blue": "#56B4E9", "bluish green": "#009E73", "yellow": "#F0E442",
           "blue": "#0072B2", "vermillion": "#D55E00", "reddish purple": "#CC79A7"}
#: what the course figures draw: the board, the truth or an ideal grid, a second estimate, residual arrows
BOARD_COLOR, TRUTH_COLOR, OTHER_COLOR = PALETTE["orange"], PALETTE["blue"], PALETTE["reddish purple"]
ARROW_COLOR = PALETTE["vermillion"]
#: a verdict's colours (good, doubtful, bad): bluish green, orange and vermillion, never a red/green pair
GOOD_COLOR, WARN_COLOR, BAD_COLOR = PALETTE["bluish green"], PALETTE["orange"], PALETTE["vermillion"]
#: the neutral greys the kit draws with besides black and white (axes, guides, backgrounds, muted text)
GREY = {"dark": "#333333", "mid": "#808080", "light": "#BFBFBF", "pale": "#EBEBEB"}
_FONT = {"font.size": 9, "axes.titlesize": 10}


class CourseFigure(Figure):
    """A matplotlib Figure that shows itself as a PNG in a notebook (no pyplot needed).

    ``alt`` is the sentence that says what the figure shows; its text form (:func:`describe`) is that
    sentence plus each panel's title, the alt text notebooks store as ``text/plain``.
    """

    alt: str = ""
    #: a figure of camera frames (made at :data:`PHOTO_DPI`): stored as JPEG, not PNG
    photo: bool = False

    def _repr_mimebundle_(self, include=None, exclude=None) -> dict:
        """What a notebook stores and shows: the PNG in an ``<img>`` with its alt text, and the alt text alone."""
        return {"text/html": figure_html(self), "text/plain": describe(self)}

    def __repr__(self) -> str:  # text/plain in a notebook: the alt text, never "<CourseFigure size ...>"
        return describe(self)


def describe(fig: Figure) -> str:
    """The alt text of a figure: its ``alt`` sentence (or a generic one), then each panel's title and axes.

    >>> fig = new_figure(2.0, 1.0); fig.alt = "A test figure."
    >>> ax = fig.add_subplot(); _ = ax.set_title("one panel"); _ = ax.set_xlabel("u (px)")
    >>> describe(fig)
    'A test figure. Panel: one panel (u (px)).'
    """
    panels = []
    for ax in fig.axes:
        title = ax.get_title() or ax.get_title("left")
        if not title and not ax.get_xlabel():  # a colour bar or an empty axes
            label = ax.get_ylabel() or ax.get_xlabel()
            if label:
                panels.append(f"colour bar: {label}")
            continue
        labels = ", ".join(x for x in (ax.get_xlabel(), ax.get_ylabel()) if x)
        text = " ".join(title.split())  # titles may hold line breaks
        panels.append(text + (f" ({labels})" if labels else ""))
    alt = getattr(fig, "alt", "") or "A figure."
    if not panels:
        return alt
    head = "Panel" if len(panels) == 1 else f"{len(panels)} panels"
    return f"{alt} {head}: " + "; ".join(panels) + "."


def figure_html(fig: Figure) -> str:
    """The figure as an HTML ``<img>``: the PNG (a photo figure's JPEG) inline, its alt text (:func:`describe`) in
    ``alt``.

    >>> fig = new_figure(1.0, 1.0); fig.alt = 'A "quoted" figure.'
    >>> figure_html(fig)[:32], figure_html(fig).split('alt=')[1]
    ('<img src="data:image/png;base64,', '"A &quot;quoted&quot; figure."/>')
    """
    if getattr(fig, "photo", False):
        buf = io.BytesIO()
        fig.savefig(buf, format="jpeg", dpi=fig.dpi, pil_kwargs={"quality": PHOTO_JPEG_QUALITY})
        mime, data = "image/jpeg", buf.getvalue()
    else:
        mime, data = "image/png", png_bytes(fig)
    src = f"data:{mime};base64,{base64.b64encode(data).decode('ascii')}"
    return f'<img src="{src}" alt="{html.escape(describe(fig), quote=True)}"/>'


def bgr(colour: str) -> tuple[int, int, int]:
    """A ``#RRGGBB`` colour as OpenCV's (blue, green, red) tuple, for drawing on frames with ``cv2``.

    >>> bgr(PALETTE["vermillion"])
    (0, 94, 213)
    """
    return int(colour[5:7], 16), int(colour[3:5], 16), int(colour[1:3], 16)


def outlined() -> list:
    """Path effects for white text on a picture or a colour map: a dark outline keeps it legible on any colour."""
    from matplotlib import patheffects

    return [patheffects.withStroke(linewidth=2.5, foreground="k")]


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
    fig.photo = dpi == PHOTO_DPI
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
    """Images (BGR or grey) side by side, titled (``width`` inches each, at least :data:`PHOTO_PANEL_IN`; more
    than two go in rows of two, so that no panel is narrower than :data:`PHOTO_MIN_PX` on a notebook's page)."""
    width = max(width, PHOTO_PANEL_IN)
    cols = min(len(images), 2)
    rows = -(-len(images) // cols)
    fig = new_figure(width * cols, width * 0.78 * rows, dpi=PHOTO_DPI)
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    for ax in axes[len(images):]:
        ax.remove()
    for ax, im, title in zip(axes, images, titles):
        show_image(ax, im, title)
    fig.alt = (f"{len(images)} camera image{'s' if len(images) > 1 else ''} side by side; "
               "the titles say what each shows.")
    return fig
