"""Figures of lens distortion and rectification: bent lines, the distortion field, undistortion error, alpha."""

from __future__ import annotations

from typing import Callable

import cv2
import numpy as np

from ... import camera as cam
from ... import duckietown as dt
from .fallback import Fallback
from .figure import TRUTH_COLOR, CourseFigure, new_figure, show_images

__all__ = ["grid_image", "distort_image", "plot_distortion_field", "plot_undistortion_error", "compare_alpha"]


def grid_image(size=dt.IMAGE_SIZE, spacing: int = 40, thickness: int = 2) -> np.ndarray:
    """A (height, width) uint8 image of straight black lines on white: what a pinhole camera sees."""
    w, h = cam.as_size(size)
    img = np.full((h, w), 255, np.uint8)
    for x in range(spacing // 2, w, spacing):
        cv2.line(img, (x, 0), (x, h - 1), 0, thickness)
    for y in range(spacing // 2, h, spacing):
        cv2.line(img, (0, y), (w - 1, y), 0, thickness)
    return img


def distort_image(ideal: np.ndarray, K, dist, ideal_K=None) -> np.ndarray:
    """What the real lens records of a scene whose pinhole image is ``ideal``.

    For every pixel of the distorted output, the ideal (undistorted) position is found
    with the kit's undistortion and ``ideal`` is sampled there. ``ideal_K`` is the
    pinhole camera of ``ideal`` (default ``K``). Pixels that see outside ``ideal`` are black.
    """
    h, w = ideal.shape[:2]
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    uv = np.column_stack([u.ravel(), v.ravel()])
    src = cam.undistort_pixels(uv, K, dist, P=K if ideal_K is None else ideal_K)
    mx = src[:, 0].reshape(h, w).astype(np.float32)
    my = src[:, 1].reshape(h, w).astype(np.float32)
    return cv2.remap(ideal, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def plot_distortion_field(distort: Callable, K, dist, size=dt.IMAGE_SIZE, step: int = 40) -> CourseFigure:
    """Where the lens moves each pixel: arrows from the pinhole position to the distorted one.

    ``distort(xy, dist)`` maps normalized to distorted normalized coordinates (the
    student's ``distort_normalized``). Colour is the displacement in pixels.
    """
    w, h = cam.as_size(size)
    u, v = np.meshgrid(np.arange(step / 2, w, step), np.arange(step / 2, h, step))
    uv = np.column_stack([u.ravel(), v.ravel()])
    xy = cam.pixel_to_normalized(uv, K)
    uv_d = cam.normalized_to_pixel(np.asarray(distort(xy, np.asarray(dist, float)), float), K)
    d = uv_d - uv
    mag = np.hypot(d[:, 0], d[:, 1])
    fig = new_figure(6.4, 4.6)
    ax = fig.add_subplot()
    # angles="xy": an arrow runs from (u, v) to (u + du, v + dv) in data coordinates, so on the image's v-down axis
    # the displacement is given as it is (negating dv would draw every vertical component backwards)
    q = ax.quiver(uv[:, 0], uv[:, 1], d[:, 0], d[:, 1], mag, angles="xy", scale_units="xy", scale=1,
                  width=0.003, cmap="magma_r")
    fig.colorbar(q, ax=ax, label="displacement [px]")
    ax.plot(K[0, 2], K[1, 2], "+", color=TRUTH_COLOR, ms=12, mew=2, label="principal point")
    ax.set(xlim=(0, w), ylim=(h, 0), aspect="equal", title="lens distortion: pinhole pixel -> recorded pixel")
    ax.legend(loc="lower right", fontsize=7)
    fig.alt = ("Arrows over the image from where a pinhole camera would see a point to where the lens puts it; "
               "the colour gives the displacement in pixels: nothing moves at the centre, many pixels at the corners.")
    return fig


def plot_undistortion_error(undistort: Callable, K, dist, size=dt.IMAGE_SIZE, step: int = 8,
                            label: str | None = None) -> CourseFigure:
    """How well an undistortion inverts the lens, over the image: ``undistort`` vs OpenCV's default.

    For every pixel of a grid, the recorded (distorted) pixel is undistorted, then
    distorted again with OpenCV's model; the map shows the round-trip error in pixels (log
    scale, floored at 1e-12 px). OpenCV's ``undistortPoints`` stops after a fixed 5
    fixed-point iterations. ``label`` names the left panel (default: from the notebook's
    :class:`~dtscal_lib.teaching.course.fallback.Fallback`, "your undistort_normalized" or the
    stand-in). Titles give the worst error as a bound below 1e-9 px (round-off digits are
    not shown: they differ between machines).
    """
    from matplotlib.colors import LogNorm

    from ..selfcheck.distortion import opencv_distort

    if label is None:  # the notebook's Fallback says whose function runs
        label = undistort.label if isinstance(undistort, Fallback) else "yours"
    w, h = cam.as_size(size)
    u, v = np.meshgrid(np.arange(0, w, step, dtype=float), np.arange(0, h, step, dtype=float))
    uv = np.column_stack([u.ravel(), v.ravel()])
    xy_d = cam.pixel_to_normalized(uv, K)
    results = {
        label: np.asarray(undistort(xy_d, np.asarray(dist, float)), float),
        "OpenCV undistortPoints (default)": cv2.undistortPoints(uv.reshape(-1, 1, 2), K, dist).reshape(-1, 2),
    }
    fig = new_figure(10, 3.6)
    axes = fig.subplots(1, 2)
    for ax, (name, xy) in zip(axes, results.items()):
        back = cam.normalized_to_pixel(opencv_distort(xy, dist), K)
        err = np.maximum(np.hypot(*(back - uv).T), 1e-12).reshape(u.shape)
        im = ax.imshow(err, extent=(0, w, h, 0), norm=LogNorm(1e-12, 100), cmap="magma")
        worst = float(err.max())
        text = "below 1e-9 px" if worst < 1e-9 else f"{worst:.2g} px"
        ax.set_title(f"{name}: worst {text}", fontsize=9)
        ax.axis("off")
    fig.colorbar(im, ax=axes, label="round-trip error [px]")
    fig.alt = ("Maps of the round-trip error (pixels, log colour scale) of undistorting then distorting every pixel: "
               "the notebook's undistortion on the left, OpenCV's default undistortPoints on the right.")
    return fig


def compare_alpha(image: np.ndarray, K, dist, maps_fn: Callable, size=None) -> tuple[CourseFigure, str]:
    """The rectified image for ``alpha = 0`` (ROS's choice) and ``alpha = 1``, with their new K.

    ``maps_fn(K, dist, new_K, size)`` makes the maps (the student's ``rectification_maps``).
    Returns (figure, text describing both new camera matrices).
    """
    h, w = image.shape[:2]
    size = (w, h) if size is None else size
    outs, titles, text = [image], ["recorded (distorted)"], []
    for alpha in (0.0, 1.0):
        newK = cam.new_camera_matrix(K, dist, size, alpha)
        mx, my = maps_fn(np.asarray(K, float), np.asarray(dist, float), newK, size)
        out = cv2.remap(image, np.asarray(mx, np.float32), np.asarray(my, np.float32), cv2.INTER_LINEAR)
        outs.append(out)
        titles.append(f"alpha = {alpha:g}: f = {newK[0, 0]:.0f}, {newK[1, 1]:.0f} px")
        valid = ((mx >= 0) & (mx <= w - 1) & (my >= 0) & (my <= h - 1)).mean()
        text.append(f"alpha = {alpha:g}: new fx, fy = {newK[0, 0]:6.1f}, {newK[1, 1]:6.1f}  "
                    f"cx, cy = {newK[0, 2]:6.1f}, {newK[1, 2]:6.1f}  valid pixels {100 * valid:5.1f} %")
    return show_images(outs, titles, width=3.4), "\n".join(text)
