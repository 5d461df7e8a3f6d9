"""Reprojection residuals of a calibration: per view and over the image (what the model is missing)."""

from __future__ import annotations

import numpy as np

from ... import camera as cam
from .figure import BOARD_COLOR, OTHER_COLOR, TRUTH_COLOR, CourseFigure, new_figure
from .session import IntrinsicViews

__all__ = ["reprojection_residuals", "rms", "plot_reprojection"]


def reprojection_residuals(views: IntrinsicViews, K, poses, dist=None, image_points=None) -> list[np.ndarray]:
    """Per view, (N, 2) pixels: detected corner minus projected board point.

    ``poses`` is a list of (R, t); ``dist`` None projects without distortion.
    ``image_points`` overrides the views' corners (e.g. undistorted corners).
    """
    pts = views.image_points if image_points is None else image_points
    return [np.asarray(uv, float) - cam.project_points(obj, R, t, K, dist)
            for (R, t), obj, uv in zip(poses, views.object_points, pts)]


def rms(residuals) -> tuple[np.ndarray, float]:
    """Per-view RMS (V,) and the RMS over all views, pixels, of a list of (N, 2) residuals.

    >>> per_view, total = rms([np.array([[3.0, 4.0]]), np.array([[0.0, 0.0]])])
    >>> per_view.tolist(), round(total, 3)
    ([5.0, 0.0], 3.536)
    """
    per_view = np.array([np.sqrt((np.asarray(r) ** 2).sum(axis=1).mean()) for r in residuals])
    total = float(np.sqrt(np.mean(np.concatenate([(np.asarray(r) ** 2).sum(axis=1) for r in residuals]))))
    return per_view, total


def plot_reprojection(residual_sets: dict, views: IntrinsicViews, image_points=None,
                      scale: float = 10.0) -> CourseFigure:
    """Per-view RMS bars for each method and, for the first method, the residual vectors on the image.

    Parameters
    ----------
    residual_sets : name -> list of (N, 2) residuals (one per view)
    scale : arrows are drawn ``scale`` times longer than the residual
    """
    fig = new_figure(10, 3.6)
    a1, a2 = fig.subplots(1, 2, width_ratios=[1.1, 1])
    names = list(residual_sets)
    width = 0.8 / len(names)
    for k, name in enumerate(names):
        per_view, total = rms(residual_sets[name])
        a1.bar(np.arange(len(per_view)) + k * width, per_view, width, label=f"{name} (all views: {total:.2f} px)",
               color=(BOARD_COLOR, TRUTH_COLOR, OTHER_COLOR)[k % 3], hatch=("", "//", "..")[k % 3],
               edgecolor="k", linewidth=0.3)  # told apart by pattern as well as colour
    a1.set(xlabel="view", ylabel="RMS reprojection error [px]", yscale="log", title="per-view error")
    a1.legend(fontsize=7)
    pts = views.image_points if image_points is None else image_points
    uv = np.concatenate(pts)
    res = np.concatenate(residual_sets[names[0]])
    # angles="xy" on the image's v-down axis: the residual as it is (a negated v would point the arrows backwards)
    a2.quiver(uv[:, 0], uv[:, 1], res[:, 0] * scale, res[:, 1] * scale, np.hypot(res[:, 0], res[:, 1]),
              angles="xy", scale_units="xy", scale=1, width=0.004, cmap="viridis")
    w, h = views.size
    a2.set(xlim=(0, w), ylim=(h, 0), aspect="equal", title=f"{names[0]}: residuals x{scale:g}")
    fig.alt = ("Left: each view's RMS reprojection error on a log scale, one bar per calibration (plain, hatched). "
               "Right: the residual vectors of every corner, magnified, drawn from where each corner was detected.")
    return fig
