"""Figures of the ground homography (the Duckiebot's extrinsic calibration): layout, errors, bird's-eye view."""

from __future__ import annotations

import cv2
import numpy as np

from ...boards import DUCKIETOWN_BOARD, Board
from ...ground import birdseye_view, draw_ground_grid, ground_grid_labels, ground_to_pixel, pixel_to_ground
from .figure import ARROW_COLOR, PHOTO_DPI, TRUTH_COLOR, CourseFigure, bgr, new_figure, outlined, show_image

__all__ = ["plot_ground_layout", "ground_error_mm", "ground_error_report", "show_ground_result"]


def plot_ground_layout(ground: np.ndarray, board: Board = DUCKIETOWN_BOARD) -> CourseFigure:
    """Top-down plot of ground points in the robot frame (x forward = up, y left = left)."""
    from matplotlib.patches import Rectangle

    g = np.asarray(ground, float)
    fig = new_figure(4.2, 4.2)
    ax = fig.add_subplot()
    ax.plot(g[:, 1], g[:, 0], "o", ms=4, color=TRUTH_COLOR)
    for k in (0, 1, board.cols):
        ax.annotate(str(k), (g[k, 1], g[k, 0]), textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.add_patch(Rectangle((-0.05, -0.04), 0.1, 0.08, fill=False, lw=1.2))
    ax.arrow(0, 0, 0, 0.06, head_width=0.01, color="k")
    ax.arrow(0, 0, 0.06, 0, head_width=0.01, color="k")
    ax.text(0.0, 0.075, "x", ha="center")
    ax.text(0.08, 0.0, "y", va="center")
    ax.set(xlim=(0.2, -0.2), ylim=(-0.06, max(0.4, g[:, 0].max() + 0.05)), aspect="equal",
           xlabel="y (left) [m]", ylabel="x (forward) [m]", title="robot frame, from above")
    fig.alt = ("Top view of the ground in the robot frame (x forward up the page, y to the left): the board's inner "
               "corners as dots in front of the robot, and the robot's x and y axes as arrows.")
    return fig


def ground_error_mm(H: np.ndarray, H_true: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """|H(p) - H_true(p)| in millimetres for (N, 2) rectified pixels, (N,) float64."""
    return 1000.0 * np.linalg.norm(pixel_to_ground(H, pixels) - pixel_to_ground(H_true, pixels), axis=1)


def ground_error_report(H: np.ndarray, H_true: np.ndarray,
                        x_bands=((0.15, 0.25), (0.25, 0.35), (0.35, 0.5), (0.5, 0.8)),
                        y_range=(-0.15, 0.15)) -> str:
    """How far a fitted ground homography is from the truth, in millimetres, per distance band.

    Parameters
    ----------
    H, H_true : (3, 3) fitted and true homographies, rectified pixel -> ground metres
    x_bands : distance bands (forward, metres) over which ground points are sampled every 1 cm
    y_range : lateral extent of the sampled ground, metres

    Returns
    -------
    str (print it)
    """
    lines = ["error against the true homography, ground sampled every 1 cm:",
             f"{'distance ahead':>18s} {'mean':>8s} {'max':>8s}"]
    for x0, x1 in x_bands:
        g = np.stack(np.meshgrid(np.arange(x0, x1 + 1e-9, 0.01), np.arange(y_range[0], y_range[1] + 1e-9, 0.01)),
                     -1).reshape(-1, 2)
        e = ground_error_mm(H, H_true, ground_to_pixel(H_true, g))
        lines.append(f"{f'{x0:.2f}-{x1:.2f} m':>18s} {e.mean():7.2f}mm {e.max():7.2f}mm")
    return "\n".join(lines)


def show_ground_result(rectified: np.ndarray, H: np.ndarray, corners: np.ndarray | None = None,
                       x_range=(0.1, 0.5), y_range=(-0.2, 0.2)) -> CourseFigure:
    """The rectified frame with the ground grid drawn back through H, and the bird's-eye view."""
    grid = draw_ground_grid(rectified, H, spacing=0.05, x_range=x_range, y_range=y_range, labels=False)
    if corners is not None:
        for k, (u, v) in enumerate(np.asarray(corners)):
            if k == 0:  # corner 0: a larger square, not only another colour
                cv2.rectangle(grid, (int(round(u)) - 5, int(round(v)) - 5), (int(round(u)) + 5, int(round(v)) + 5),
                              bgr(ARROW_COLOR), -1)
            else:
                cv2.circle(grid, (int(round(u)), int(round(v))), 3, bgr(TRUTH_COLOR), -1)
    bird = birdseye_view(rectified, H, x_range=x_range, y_range=y_range, px_per_m=800)
    fig = new_figure(11.0, 5.2, dpi=PHOTO_DPI)
    a1, a2 = fig.subplots(1, 2, width_ratios=[1.2, 1])
    show_image(a1, grid, "rectified frame + 5 cm ground grid (corner 0: the square)")
    for text, u, v in ground_grid_labels(H, grid.shape[1::-1], spacing=0.05, x_range=x_range):
        # drawn by matplotlib, not into the frame: the frame is scaled down, the label keeps the figure's text size
        a1.text(u + 3, v - 3, text, fontsize=11, color="w", weight="bold", path_effects=outlined())
    bird_bgr = bird if bird.ndim == 3 else cv2.cvtColor(bird, cv2.COLOR_GRAY2BGR)
    a2.imshow(cv2.cvtColor(bird_bgr, cv2.COLOR_BGR2RGB), extent=(y_range[1], y_range[0], x_range[0], x_range[1]))
    a2.set(xlabel="y (left) [m]", ylabel="x (forward) [m]")
    a2.set_title("bird's-eye view", fontsize=9)
    fig.alt = ("Left: the rectified frame with a 5 cm ground grid drawn back through the homography and the board's "
               "corners as dots. Right: the bird's-eye view, the rectified image warped onto the ground.")
    return fig
