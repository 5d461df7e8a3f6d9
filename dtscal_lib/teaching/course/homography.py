"""Figures of the plane homography (activity text, eqs. (3)-(6)): a frame straightened, residuals, conditioning."""

from __future__ import annotations

from typing import Callable, Sequence

import cv2
import numpy as np

from ...boards import DUCKIETOWN_BOARD, Board
from ...duckietown import IMAGE_SIZE
from ...homography import apply_homography, transfer_rms
from .fallback import Fallback
from .figure import (ARROW_COLOR, BOARD_COLOR, OTHER_COLOR, PHOTO_DPI, TRUTH_COLOR, CourseFigure, draw_board,
                     image_axes, new_figure)

__all__ = ["fronto_parallel_view", "warp_figure", "unnormalized_dlt", "conditioning_experiment",
           "conditioning_summary", "conditioning_figure", "residual_figure"]


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
                px_per_square: int = 40, margin_squares: float = 1.5) -> CourseFigure:
    """Left: the frame with its detected corners; right: the fronto-parallel view with the ideal grid."""
    fig = new_figure(11.0, 4.5, dpi=PHOTO_DPI)
    a, b = fig.subplots(1, 2, width_ratios=[image.shape[1] / image.shape[0], warped.shape[1] / warped.shape[0]])
    a.imshow(image, cmap="gray", vmin=0, vmax=255)
    draw_board(a, corners, board)
    image_axes(a, (image.shape[1], image.shape[0]), "recorded frame and detected corners")
    b.imshow(warped, cmap="gray", vmin=0, vmax=255)
    s, m = px_per_square, margin_squares
    ideal = (board.object_points()[:, :2] / board.square + m) * s
    draw_board(b, ideal, board, color=TRUTH_COLOR)
    image_axes(b, (warped.shape[1], warped.shape[0]), "warped with inv(H): fronto-parallel")
    fig.alt = ("Left: the recorded camera frame with the detected board corners drawn as a grid. Right: the same frame "
               "warped with the inverse homography so the board looks straight on, with the ideal square grid on top.")
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


def _label(estimate: Callable) -> str:
    if isinstance(estimate, Fallback):
        return f"normalized DLT: {estimate.label}" if estimate.uses_student else estimate.label
    return f"normalized DLT: {getattr(estimate, '__name__', 'yours')}"


def conditioning_experiment(estimate: Callable, offsets: Sequence[float], sigma: float = 0.0,
                            n_points: int = 35, seed: int = 0) -> dict:
    """Transfer error of a homography fit as the source coordinates move away from the origin.

    For each offset the same pixel->pixel mapping is sampled with source points spread
    over a 640 x 480 area shifted by ``offset`` in x and y (destination noise ``sigma``
    pixels); it is fitted by ``estimate`` (the notebook's normalized DLT: the student's or,
    while it does not work, the kit's :func:`dtscal_lib.homography.estimate_homography`), by
    :func:`unnormalized_dlt` and by ``cv2.findHomography`` (method 0).

    Returns
    -------
    dict with ``offset``, ``normalized``, ``unnormalized``, ``opencv`` (len(offsets),) RMS
    pixels and ``label``, what the normalized fit is
    """
    rng = np.random.default_rng(seed)
    base = np.column_stack([rng.uniform(0, 640, n_points), rng.uniform(0, 480, n_points)])
    H0 = np.array([[0.9, 0.12, 40.0], [-0.05, 1.1, 25.0], [2e-4, 4e-4, 1.0]])
    noise = rng.normal(0.0, sigma, size=(n_points, 2)) if sigma > 0 else np.zeros((n_points, 2))
    dst = apply_homography(H0, base) + noise
    out = {k: [] for k in ("offset", "normalized", "unnormalized", "opencv")}
    for off in offsets:
        src = base + off
        out["offset"].append(off)
        out["normalized"].append(transfer_rms(estimate(src, dst), src, dst))
        out["unnormalized"].append(transfer_rms(unnormalized_dlt(src, dst), src, dst))
        out["opencv"].append(transfer_rms(cv2.findHomography(src, dst, 0)[0], src, dst))
    res = {k: np.asarray(v, dtype=float) for k, v in out.items()}
    res["label"] = _label(estimate)
    return res


def conditioning_summary(results: dict, roundoff: float = 1e-8, large: float = 1e-6) -> str:
    """What :func:`conditioning_experiment` shows, in words that do not depend on the machine.

    The errors of noise-free fits are floating-point round-off: their digits change with the
    BLAS library and the CPU. So the summary compares them with two fixed levels, each at
    least 10x away from what any machine computes here, and never prints the digits:
    ``roundoff`` (the normalized DLT stays below it at every offset) and ``large`` (what
    the unnormalized DLT exceeds far from the origin).
    """
    lines = ["noise-free points, RMS transfer error:"]
    names = {"normalized": results["label"], "unnormalized": "DLT without normalization",
             "opencv": "cv2.findHomography (refined only to a tolerance)"}
    far = results["offset"][-1]
    for key, name in names.items():
        err = results[key]
        if np.all(err < roundoff):
            what = f"below {roundoff:g} px at every offset"
        elif err[-1] > large:
            what = f"above {large:g} px at offset {far:.0e}"
        else:
            what = f"above {roundoff:g} px at some offset"
        lines.append(f"  {name}: {what}")
    return "\n".join(lines)


def conditioning_figure(results: dict, title: str = "noise-free points") -> CourseFigure:
    """Log-log plot of :func:`conditioning_experiment` results: transfer error vs offset, per method."""
    fig = new_figure(4.8, 3.0)
    ax = fig.add_subplot()
    off = np.maximum(results["offset"], 1.0)
    ax.loglog(off, np.maximum(results["unnormalized"], 1e-16), "o-", color=BOARD_COLOR,
              label="DLT without normalization")
    ax.loglog(off, np.maximum(results["normalized"], 1e-16), "s-", label=results["label"], color=TRUTH_COLOR)
    ax.loglog(off, np.maximum(results["opencv"], 1e-16), "^--", color=OTHER_COLOR,
              label="cv2.findHomography", alpha=0.7)
    ax.set_xlabel("offset of the source coordinates (px)")
    ax.set_ylabel("RMS transfer error (px)")
    ax.set_title(title, fontsize=9)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=7)
    fig.alt = ("Log-log plot of the RMS transfer error (pixels) of each homography fit against how far the points "
               "lie from the origin; one line per method.")
    return fig


def residual_figure(src: np.ndarray, dst: np.ndarray, fits: dict[str, np.ndarray], scale: float = 50.0,
                    size: tuple[int, int] = IMAGE_SIZE) -> CourseFigure:
    """Residual arrows ``H src - dst`` of several fits (name -> H), magnified ``scale`` times."""
    fig = new_figure(4.2 * len(fits), 3.2)
    axes = fig.subplots(1, len(fits), squeeze=False)[0]
    for ax, (name, H) in zip(axes, fits.items()):
        r = apply_homography(H, src) - dst
        rms = float(np.sqrt(np.mean(np.sum(r ** 2, axis=1))))
        ax.plot(dst[:, 0], dst[:, 1], ".", color="k", ms=3)
        ax.quiver(dst[:, 0], dst[:, 1], r[:, 0], r[:, 1], angles="xy", scale_units="xy", scale=1 / scale,
                  color=ARROW_COLOR, width=0.004)
        image_axes(ax, size, f"{name}: RMS {rms:.3f} px (arrows x{scale:g})")
    fig.alt = (f"Residual arrows of {len(fits)} homography fits on the detected corners, one panel per fit, "
               f"each arrow from a corner to where the fit puts it, magnified {scale:g} times; "
               "the RMS is in each title.")
    return fig
