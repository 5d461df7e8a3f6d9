"""Zhang's closed form in the course (activity text, eqs. (12)-(13)): views, K tables, poses, degradation."""

from __future__ import annotations

from typing import Callable

import cv2
import numpy as np

from ... import camera as cam
from ...boards import DUCKIETOWN_BOARD, Board
from ...errors import DtscalError
from .figure import PHOTO_DPI, PHOTO_PANEL_IN, CourseFigure, new_figure
from .projection import sample_views
from .session import IntrinsicViews, board_homographies, find_corners

__all__ = ["show_views", "intrinsics_table", "pose_from_homography_opencv", "plot_board_poses",
           "degradation_experiment"]


def show_views(views: IntrinsicViews, board: Board = DUCKIETOWN_BOARD, cols: int = 2) -> CourseFigure:
    """A montage of a few recorded frames with the detected corners drawn."""
    if not views.images:
        fig = new_figure(5, 3.5)
        ax = fig.add_subplot()
        for uv in views.image_points:
            ax.plot(uv[:, 0], uv[:, 1], ".", ms=2)
        w, h = views.size
        ax.set(xlim=(0, w), ylim=(h, 0), aspect="equal", title=f"{views.n_views} views (corners only)")
        return fig
    n = len(views.images)
    rows = int(np.ceil(n / cols))
    fig = new_figure(PHOTO_PANEL_IN * cols, PHOTO_PANEL_IN * 0.75 * rows, dpi=PHOTO_DPI)
    axes = np.ravel(fig.subplots(rows, cols, squeeze=False))
    for ax in axes:
        ax.axis("off")
    for ax, image in zip(axes, views.images):
        c = find_corners(image, board, thorough=False)
        shown = image.copy() if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
        if c is not None:
            cv2.drawChessboardCorners(shown, board.pattern_size, c.reshape(-1, 1, 2).astype(np.float32), True)
        ax.imshow(cv2.cvtColor(shown, cv2.COLOR_BGR2RGB))
    fig.suptitle(f"{views.source}: {views.n_views} views used", fontsize=9)
    fig.alt = ("A few of the recorded frames in which the board was found, the detected corners drawn on each.")
    return fig


#: width of the name column of :func:`intrinsics_table`
NAME_WIDTH = 44


def intrinsics_table(estimates: dict, K_true: np.ndarray | None = None) -> str:
    """A text table of fx, fy, cx, cy, s for several estimates of K (and their error vs the truth).

    Parameters
    ----------
    estimates : name -> (3, 3) K
    K_true : optional (3, 3) truth, adds an error column in pixels

    Returns
    -------
    str (print it)

    Examples
    --------
    >>> print(intrinsics_table({"a": np.eye(3)}))    # doctest: +NORMALIZE_WHITESPACE
    fx fy cx cy s
    a 1.00 1.00 0.00 0.00 0.00
    """
    long = max([len(n) for n in estimates] + [5])
    if long > NAME_WIDTH:
        raise DtscalError(f"estimate names must be at most {NAME_WIDTH} characters; "
                          f"shorten {max(estimates, key=len)!r}")
    head = f"{'':{NAME_WIDTH}s}{'fx':>9s}{'fy':>9s}{'cx':>9s}{'cy':>9s}{'s':>8s}"
    if K_true is not None:
        head += f"{'max |err|':>11s}"
    lines = [head]
    rows = dict(estimates)
    if K_true is not None:
        rows = {"truth": K_true, **rows}
    idx = ([0, 1, 0, 1, 0], [0, 1, 2, 2, 1])
    for name, K in rows.items():
        K = np.asarray(K, float)
        line = f"{name:{NAME_WIDTH}s}" + "".join(f"{K[i, j]:9.2f}" for i, j in ((0, 0), (1, 1), (0, 2), (1, 2)))
        line += f"{K[0, 1]:8.2f}"
        if K_true is not None and name != "truth":
            line += f"{np.abs(K[idx] - K_true[idx]).max():9.2f}px"
        lines.append(line)
    return "\n".join(lines)


def pose_from_homography_opencv(K: np.ndarray, H: np.ndarray, board: Board = DUCKIETOWN_BOARD):
    """Board pose (R, t) consistent with ``H``, by OpenCV: ``solvePnP`` (IPPE) on the board mapped by H.

    A stand-in for the notebook's ``extrinsics_from_homography`` (not the same algorithm).
    Returns (3, 3) rotation and (3,) translation.
    """
    obj = board.object_points()
    p = np.column_stack([obj[:, :2], np.ones(len(obj))]) @ np.asarray(H, float).T
    uv = p[:, :2] / p[:, 2:]
    ok, rvec, tvec = cv2.solvePnP(obj, uv, np.asarray(K, float), None, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        raise DtscalError("OpenCV's solvePnP found no pose for this homography")
    return cv2.Rodrigues(rvec)[0], tvec.ravel()


def plot_board_poses(poses, board: Board = DUCKIETOWN_BOARD,
                     title: str = "board poses (camera frame)") -> CourseFigure:
    """3-D view of the board poses in the camera frame (camera at the origin, looking along +z)."""
    import matplotlib as mpl
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    fig = new_figure(5.5, 4.2)
    ax = fig.add_subplot(projection="3d")
    s = board.square
    outline = np.array([[-s, -s, 0], [board.cols * s, -s, 0], [board.cols * s, board.rows * s, 0],
                        [-s, board.rows * s, 0]])
    cmap = mpl.colormaps["viridis"]
    for k, (R, t) in enumerate(poses):
        P = outline @ np.asarray(R).T + np.asarray(t).reshape(3)
        # plot with z (depth) as the plot's y axis and -y (image up) as the plot's z axis
        poly = Poly3DCollection([P[:, [0, 2, 1]] * [1, 1, -1]], alpha=0.45,
                                facecolor=cmap(k / max(1, len(poses) - 1)), edgecolor="k", linewidths=0.4)
        ax.add_collection3d(poly)
    f = 0.06
    for c in ([-1, -0.75], [1, -0.75], [1, 0.75], [-1, 0.75]):
        ax.plot([0, c[0] * f], [0, 1.2 * f], [0, -c[1] * f], "k-", lw=0.8)
    ax.scatter([0], [0], [0], c="k", s=15)
    allp = np.array([np.asarray(t).reshape(3) for _, t in poses])
    lim = max(0.3, float(np.abs(allp).max()) + 0.1)
    ax.set(xlim=(-lim / 2, lim / 2), ylim=(0, lim), zlim=(-lim / 2, lim / 2),
           xlabel="x [m]", ylabel="z (depth) [m]", zlabel="-y (up) [m]", title=title)
    ax.view_init(elev=20, azim=-60)
    fig.alt = ("The board poses recovered from each view, drawn in 3-D around the camera at the origin "
               "looking along +z; one rectangle per view.")
    return fig


def degradation_experiment(estimate_K: Callable, K_true: np.ndarray, *, view_counts=(3, 4, 6, 10, 20),
                           tilts=((0.5, 2.0), (2.0, 5.0), (5.0, 10.0), (10.0, 20.0), (20.0, 45.0)),
                           noise_px: float = 0.2, trials: int = 10, seed: int = 7) -> str:
    """How the closed-form K degrades with fewer views and with nearly parallel views.

    Synthetic, distortion-free views of the board with ``noise_px`` of corner noise; the
    homographies are OpenCV's, ``estimate_K(Hs)`` is the function under study. Each cell is
    the median over ``trials`` random sets of the largest error of fx, fy, cx, cy (pixels);
    medians above 100 px print as ``> 100`` (their digits depend on round-off).

    The configuration the two tables share (10 views tilted 20-45 degrees) is run once and printed in both.

    Returns
    -------
    str, two small tables (print it)
    """
    obj = DUCKIETOWN_BOARD.object_points()
    idx = ([0, 1, 0, 1], [0, 1, 2, 2])

    done: dict = {}  # one configuration, one answer: a set that appears in both tables is the same set

    def run(n, tilt, s):
        key = (n, tuple(float(a) for a in tilt))
        if key not in done:
            done[key] = _run(n, tilt, s)
        return done[key]

    def _run(n, tilt, s):
        rng = np.random.default_rng(s)
        errs, refused = [], 0
        for trial in range(trials):
            poses = sample_views(K_true, n, seed=s * 1000 + trial, min_tilt_deg=tilt[0], max_tilt_deg=tilt[1])
            pts = [cam.project_points(obj, R, t, K_true) + rng.normal(scale=noise_px, size=(len(obj), 2))
                   for R, t in poses]
            try:
                K = np.asarray(estimate_K(board_homographies([obj] * n, pts)), float)
                e = float(np.abs(K[idx] - K_true[idx]).max())
                errs.append(e if np.isfinite(e) else np.inf)
            except Exception:  # a degenerate set that the estimator rightly refuses
                refused += 1
        if not errs:
            med = f"{'-':>10s}"
        else:  # huge errors come from nearly singular systems, whose digits round-off decides: give a bound
            m = float(np.median(errs))
            med = f"{m:10.1f}" if m < 100 else f"{'> 100':>10s}"
        return med + (f" ({refused} refused)" if refused else "")

    lines = [f"noise {noise_px} px, median over {trials} random view sets of max |error| of fx, fy, cx, cy [px]",
             "", f"{'views (tilt 20-45 deg)':>24s}  error"]
    for n in view_counts:
        lines.append(f"{n:>24d}  {run(n, (20.0, 45.0), seed + n)}")
    lines += ["", f"{'tilt from camera axis':>24s}  error (10 views)"]
    for k, tilt in enumerate(tilts):
        lines.append(f"{f'{tilt[0]:g}-{tilt[1]:g} deg':>24s}  {run(10, tilt, seed + 100 + k)}")
    return "\n".join(lines)
