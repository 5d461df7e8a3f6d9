"""Plumbing and figures for the course notebooks 03-05 (intrinsics, distortion, ground).

The notebooks hold the student's functions, the explanations and the checks; everything
else they show (loading the recorded session, detecting corners, tables, plots) lives
here so the notebooks stay short. Nothing here implements an exercise: where a notebook
needs a result before the student's function works, :func:`use_or_fallback` substitutes
OpenCV or the kit's own production code and says so in the output.

All figures are small PNGs (call :func:`notebook_style` once) and deterministic.
"""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import cv2
import numpy as np

from . import camera as cam
from . import duckietown as dt
from .boards import DUCKIETOWN_BOARD, Board
from .errors import DtscalError

__all__ = [
    "notebook_style", "use_or_fallback", "Fallback",
    "IntrinsicViews", "load_intrinsic_views", "find_corners", "board_homographies",
    "show_views", "intrinsics_table", "pose_from_homography_opencv", "reprojection_residuals",
    "plot_reprojection", "plot_board_poses", "sample_views", "degradation_experiment",
    "grid_image", "distort_image", "show_images", "plot_distortion_field", "plot_undistortion_error",
    "compare_alpha", "ExtrinsicCapture", "load_extrinsic_capture", "plot_ground_layout",
    "notebook_function", "ground_error_mm", "ground_error_report", "show_ground_result",
    "distorted_board_frame",
]

FIG_DPI = 80
#: photo-like figures (camera frames) compress poorly as PNG: a lower resolution keeps notebooks small
PHOTO_DPI = 70


def notebook_style() -> None:
    """Small, deterministic PNG figures: sets matplotlib's inline dpi and font size."""
    import matplotlib as mpl

    mpl.rcParams.update({"figure.dpi": FIG_DPI, "savefig.dpi": FIG_DPI, "font.size": 9,
                         "figure.figsize": (7.0, 3.6), "axes.titlesize": 10})


# =========================================================================== student or fallback
@dataclass
class Fallback:
    """A callable that runs the student's function, or a stand-in while it does not work.

    Made by :func:`use_or_fallback`; ``uses_student`` says which one runs.
    """

    name: str
    student: Callable
    fallback: Callable
    fallback_name: str
    uses_student: bool
    reason: str = ""
    _warned: list = field(default_factory=list, repr=False)

    @property
    def chosen(self) -> Callable:
        """The function in use, without the per-call fallback (its errors propagate)."""
        return self.student if self.uses_student else self.fallback

    def __call__(self, *args, **kwargs):
        if self.uses_student:
            try:
                return self.student(*args, **kwargs)
            except Exception as exc:  # the student's code failed on the real data
                if not self._warned:
                    self._warned.append(True)
                    _banner(f"your `{self.name}` raised {type(exc).__name__}: {exc}",
                            f"using {self.fallback_name} for this call (and any later failing call) instead")
                return self.fallback(*args, **kwargs)
        return self.fallback(*args, **kwargs)


def _banner(what: str, then: str) -> None:
    line = "!" * 78
    print(f"{line}\n!! {what}\n!! -> {then}\n{line}")


def _unavailable(*args, **kwargs):
    raise NotImplementedError("the student's function could not be loaded")


def use_or_fallback(student: Callable | None, fallback: Callable, *, name: str | None = None,
                    check: Callable | None = None, fallback_name: str = "OpenCV's result") -> Fallback:
    """Decide once whether the notebook uses the student's function or a stand-in.

    The student's function is used when its self-check passes (``check(fn).status ==
    "pass"``, run silently); without a check it is always tried, and any call that raises
    falls back (with a message). Otherwise a clearly visible message says what the notebook
    uses instead, so later cells still run.

    Parameters
    ----------
    student : the student's function (None when it could not be loaded)
    fallback : same signature; OpenCV or the kit's own implementation
    name : the function's name in messages (default ``student.__name__``)
    check : the notebook's self-check for this function
    fallback_name : what the stand-in is, for the message

    Returns
    -------
    Fallback, a callable with the student's signature
    """
    name = name or getattr(student, "__name__", "your function")
    if student is None:
        _banner(f"your `{name}` is not available",
                f"using {fallback_name} until your function works (the cells below still run)")
        return Fallback(name, _unavailable, fallback, fallback_name, False, "is not available")
    if check is not None:
        with contextlib.redirect_stdout(io.StringIO()):
            status = check(student).status
        ok = status == "pass"
        reason = "is not implemented yet" if status == "not implemented yet" else "does not pass its self-check yet"
    else:
        ok, reason = True, ""
    if not ok:
        _banner(f"`{name}` {reason}",
                f"using {fallback_name} until your function works (the cells below still run)")
    else:
        print(f"using your `{name}`")
    return Fallback(name, student, fallback, fallback_name, ok, "" if ok else reason)


# =========================================================================== recorded session
def _datasets():
    try:
        from . import datasets  # written by another part of the kit
    except ImportError:
        return None
    return datasets


def find_corners(image: np.ndarray, board: Board = DUCKIETOWN_BOARD, thorough: bool = True) -> np.ndarray | None:
    """Inner corners of ``board`` in an image, (N, 2) float64 pixels, or None.

    The kit's fast detector (:func:`dtscal_lib.detect.detect_board`, ROS's rules); with
    ``thorough``, the still-frame detector that also runs OpenCV's full search
    (:func:`dtscal_lib.detect.detect_board_still`: slower when there is no board, but it
    finds boards the fast region search misses, e.g. a far board on a textured floor).
    """
    from .detect import detect_board, detect_board_still

    det = (detect_board_still if thorough else detect_board)(image, board)
    return np.asarray(det.corners, dtype=np.float64).reshape(-1, 2) if det.found else None


def board_homographies(object_points: Sequence[np.ndarray], image_points: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Per view, OpenCV's least-squares homography board metres (X, Y) -> pixels, ``H[2, 2] = 1``.

    Parameters
    ----------
    object_points : V arrays (N, 3) (z = 0) or (N, 2)
    image_points : V arrays (N, 2) pixels
    """
    Hs = []
    for obj, img in zip(object_points, image_points):
        H, _ = cv2.findHomography(np.asarray(obj, float)[:, :2], np.asarray(img, float).reshape(-1, 2), 0)
        if H is None:
            raise DtscalError("OpenCV found no homography for a view; its corners are degenerate")
        Hs.append(H / H[2, 2])
    return Hs


@dataclass
class IntrinsicViews:
    """Board views for intrinsic calibration.

    Attributes
    ----------
    images : a few raw frames for display (may be empty)
    image_points : V arrays (N, 2) float64 detected corners, pixels
    object_points : V arrays (N, 3) float64 board points, metres, z = 0
    size : (width, height)
    K_true, dist_true : (3, 3), (5,) the camera that made the recording
    source : where the views come from
    """

    images: list
    image_points: list
    object_points: list
    size: tuple[int, int]
    K_true: np.ndarray
    dist_true: np.ndarray
    source: str

    @property
    def n_views(self) -> int:
        return len(self.image_points)


def _truth_camera(truth: dict) -> tuple[np.ndarray, np.ndarray]:
    """(K, dist) of the recorded camera from :func:`dtscal_lib.datasets.load_truth`."""
    return cam.as_K(truth["camera"]["K"]), cam.as_dist(truth["camera"]["dist"])


def _load_truth(ds) -> dict | None:
    if ds is None:
        return None
    try:
        return ds.load_truth()
    except (DtscalError, OSError) as exc:
        print(f"no usable recorded session ({exc}); using a synthetic stand-in")
        return None


def _synthetic_intrinsic_views(n_views: int, seed: int) -> IntrinsicViews:
    """Noisy synthetic detections of the Duckiebot camera (used only if no recording exists)."""
    K, d = dt.default_K(), dt.default_dist()
    obj = DUCKIETOWN_BOARD.object_points()
    rng = np.random.default_rng(seed)
    imgs, objs = [], []
    for R, t in sample_views(K, n_views, seed, max_tilt_deg=45.0, dist=d):
        uv = cam.project_points(obj, R, t, K, d) + rng.normal(scale=0.15, size=(len(obj), 2))
        imgs.append(uv)
        objs.append(obj.copy())
    return IntrinsicViews([], imgs, objs, dt.IMAGE_SIZE, K, d, "synthetic detections (no recording found)")


def load_intrinsic_views(max_views: int = 25, n_images: int = 6, board: Board = DUCKIETOWN_BOARD,
                         step: int = 2, seed: int = 0) -> IntrinsicViews:
    """The recorded intrinsic-calibration session: frames, detected corners and the truth.

    Reads ``data/session`` through :mod:`dtscal_lib.datasets`, detects the board in every
    ``step``-th frame (frames where it is not found are skipped) and keeps at most
    ``max_views`` detections, evenly spread over the recording. Without a recording, noisy
    synthetic detections of the default Duckiebot camera are returned instead (``source``
    says so).
    """
    ds = _datasets()
    truth = _load_truth(ds)
    if truth is None:
        return _synthetic_intrinsic_views(max_views, seed)
    K, d = _truth_camera(truth)
    images, pts, n_frames = [], [], 0
    for _index, image in ds.intrinsic_frames(step=step):
        n_frames += 1
        c = find_corners(image, board, thorough=False)
        if c is not None:
            images.append(image)
            pts.append(c)
    if len(pts) < 3:
        raise DtscalError(f"the board was found in only {len(pts)} recorded frames; the recording looks broken")
    keep = np.unique(np.linspace(0, len(pts) - 1, min(max_views, len(pts))).round().astype(int))
    shown = keep[np.unique(np.linspace(0, len(keep) - 1, min(n_images, len(keep))).round().astype(int))]
    h, w = images[0].shape[:2]
    return IntrinsicViews([images[i] for i in shown], [pts[i] for i in keep],
                          [board.object_points() for _ in keep], (w, h), K, d,
                          f"recorded session: board found in {len(pts)} of {n_frames} frames read")


# =========================================================================== notebook 03 figures
def show_views(views: IntrinsicViews, board: Board = DUCKIETOWN_BOARD, cols: int = 3):
    """A montage of a few recorded frames with the detected corners drawn."""
    import matplotlib.pyplot as plt

    if not views.images:
        fig, ax = plt.subplots(figsize=(5, 3.5))
        for uv in views.image_points:
            ax.plot(uv[:, 0], uv[:, 1], ".", ms=2)
        w, h = views.size
        ax.set(xlim=(0, w), ylim=(h, 0), aspect="equal", title=f"{views.n_views} views (corners only)")
        fig.tight_layout()
        return fig
    n = len(views.images)
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(2.6 * cols, 2.0 * rows), dpi=PHOTO_DPI)
    for ax in np.ravel(axes):
        ax.axis("off")
    for ax, image in zip(np.ravel(axes), views.images):
        c = find_corners(image, board, thorough=False)
        shown = image.copy() if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
        if c is not None:
            cv2.drawChessboardCorners(shown, board.pattern_size, c.reshape(-1, 1, 2).astype(np.float32), True)
        ax.imshow(cv2.cvtColor(shown, cv2.COLOR_BGR2RGB))
    fig.suptitle(f"{views.source}: {views.n_views} views used", fontsize=9)
    fig.tight_layout()
    return fig


def intrinsics_table(estimates: dict, K_true: np.ndarray | None = None) -> str:
    """A text table of fx, fy, cx, cy, s for several estimates of K (and their error vs the truth).

    Parameters
    ----------
    estimates : name -> (3, 3) K
    K_true : optional (3, 3) truth, adds an error column in pixels

    Returns
    -------
    str (print it)
    """
    head = f"{'':34s}{'fx':>9s}{'fy':>9s}{'cx':>9s}{'cy':>9s}{'s':>8s}"
    if K_true is not None:
        head += f"{'max |err|':>11s}"
    lines = [head]
    rows = dict(estimates)
    if K_true is not None:
        rows = {"truth": K_true, **rows}
    for name, K in rows.items():
        K = np.asarray(K, float)
        line = f"{name:34.34s}" + "".join(f"{K[i, j]:9.2f}" for i, j in ((0, 0), (1, 1), (0, 2), (1, 2))) + f"{K[0, 1]:8.2f}"
        if K_true is not None and name != "truth":
            idx = ([0, 1, 0, 1, 0], [0, 1, 2, 2, 1])
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


def reprojection_residuals(views: IntrinsicViews, K, poses, dist=None, image_points=None) -> list[np.ndarray]:
    """Per view, (N, 2) pixels: detected corner minus projected board point.

    ``poses`` is a list of (R, t); ``dist`` None projects without distortion.
    ``image_points`` overrides the views' corners (e.g. undistorted corners).
    """
    pts = views.image_points if image_points is None else image_points
    out = []
    for (R, t), obj, uv in zip(poses, views.object_points, pts):
        out.append(np.asarray(uv, float) - cam.project_points(obj, R, t, K, dist))
    return out


def plot_reprojection(residual_sets: dict, views: IntrinsicViews, image_points=None, scale: float = 10.0):
    """Per-view RMS bars for each method and, for the first method, the residual vectors on the image.

    Parameters
    ----------
    residual_sets : name -> list of (N, 2) residuals (one per view)
    scale : arrows are drawn ``scale`` times longer than the residual
    """
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.6), gridspec_kw={"width_ratios": [1.1, 1]})
    names = list(residual_sets)
    width = 0.8 / len(names)
    for k, name in enumerate(names):
        rms = [np.sqrt((r**2).sum(axis=1).mean()) for r in residual_sets[name]]
        total = np.sqrt(np.mean(np.concatenate([(r**2).sum(axis=1) for r in residual_sets[name]])))
        a1.bar(np.arange(len(rms)) + k * width, rms, width, label=f"{name} (all views: {total:.2f} px)")
    a1.set(xlabel="view", ylabel="RMS reprojection error [px]", yscale="log", title="per-view error")
    a1.legend(fontsize=7)
    first = residual_sets[names[0]]
    pts = views.image_points if image_points is None else image_points
    uv = np.concatenate(pts)
    res = np.concatenate(first)
    a2.quiver(uv[:, 0], uv[:, 1], res[:, 0] * scale, -res[:, 1] * scale, np.hypot(res[:, 0], res[:, 1]),
              angles="xy", scale_units="xy", scale=1, width=0.004, cmap="viridis")
    w, h = views.size
    a2.set(xlim=(0, w), ylim=(h, 0), aspect="equal", title=f"{names[0]}: residuals x{scale:g}")
    fig.tight_layout()
    return fig


def plot_board_poses(poses, board: Board = DUCKIETOWN_BOARD, title: str = "board poses (camera frame)"):
    """3-D view of the board poses in the camera frame (camera at the origin, looking along +z)."""
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    fig = plt.figure(figsize=(5.5, 4.2))
    ax = fig.add_subplot(projection="3d")
    s = board.square
    outline = np.array([[-s, -s, 0], [board.cols * s, -s, 0], [board.cols * s, board.rows * s, 0],
                        [-s, board.rows * s, 0]])
    cmap = plt.get_cmap("viridis")
    for k, (R, t) in enumerate(poses):
        P = outline @ np.asarray(R).T + np.asarray(t).reshape(3)
        # plot with z (depth) as the plot's y axis and -y (image up) as the plot's z axis
        poly = Poly3DCollection([P[:, [0, 2, 1]] * [1, 1, -1]], alpha=0.45,
                                facecolor=cmap(k / max(1, len(poses) - 1)), edgecolor="k", linewidths=0.4)
        ax.add_collection3d(poly)
    f = 0.06
    for c in ([-1, -0.75], [1, -0.75], [1, 0.75], [-1, 0.75]):
        ax.plot([0, c[0] * f], [0, 1.2 * f], [0, -c[1] * f], "k-", lw=0.8)
    ax.scatter([0], [0], [0], c="r", s=15)
    allp = np.array([np.asarray(t).reshape(3) for _, t in poses])
    lim = max(0.3, float(np.abs(allp).max()) + 0.1)
    ax.set(xlim=(-lim / 2, lim / 2), ylim=(0, lim), zlim=(-lim / 2, lim / 2),
           xlabel="x [m]", ylabel="z (depth) [m]", zlabel="-y (up) [m]", title=title)
    ax.view_init(elev=20, azim=-60)
    fig.tight_layout()
    return fig


def sample_views(K: np.ndarray, n: int, seed: int, *, min_tilt_deg: float = 10.0, max_tilt_deg: float = 40.0,
                 distance: tuple[float, float] = (0.3, 0.6), dist=None, size=dt.IMAGE_SIZE,
                 board: Board = DUCKIETOWN_BOARD) -> list[tuple[np.ndarray, np.ndarray]]:
    """Random board poses (R, t) in front of a camera with the whole board inside the image.

    The board is tilted by ``min_tilt_deg`` .. ``max_tilt_deg`` about a random axis in the
    image plane, ``distance`` metres away, and placed anywhere its corners stay 8 px inside
    the image. Deterministic for a given ``seed``.
    """
    rng = np.random.default_rng(seed)
    obj = board.object_points()
    centre = obj.mean(axis=0)
    w, h = size
    out: list = []
    tries = 0
    while len(out) < n:
        tries += 1
        if tries > 200 * n:
            raise DtscalError("could not place the board inside the image; widen the distance range")
        phi = rng.uniform(0, 2 * np.pi)
        axis = np.array([np.cos(phi), np.sin(phi), 0.0])
        tilt = np.deg2rad(rng.uniform(min_tilt_deg, max_tilt_deg))
        spin = np.deg2rad(rng.uniform(-20, 20))
        R = cv2.Rodrigues(axis * tilt)[0] @ cv2.Rodrigues(np.array([0, 0, spin]))[0]
        z = rng.uniform(*distance)
        aim = np.array([rng.uniform(-0.35, 0.35) * z, rng.uniform(-0.25, 0.25) * z, z])
        t = aim - R @ centre
        try:
            uv = cam.project_points(obj, R, t, K, dist)
        except DtscalError:
            continue
        m = dt.BORDER_MARGIN_PX
        if np.all((uv[:, 0] > m) & (uv[:, 0] < w - m) & (uv[:, 1] > m) & (uv[:, 1] < h - m)):
            out.append((R, t))
    return out


def degradation_experiment(estimate_K: Callable, K_true: np.ndarray, *, view_counts=(3, 4, 6, 10, 20),
                           tilts=((0.5, 2.0), (2.0, 5.0), (5.0, 10.0), (10.0, 20.0), (20.0, 45.0)),
                           noise_px: float = 0.2, trials: int = 10, seed: int = 7) -> str:
    """How the closed-form K degrades with fewer views and with nearly parallel views.

    Synthetic, distortion-free views of the board with ``noise_px`` of corner noise; the
    homographies are OpenCV's, ``estimate_K(Hs)`` is the function under study. Each cell is
    the median over ``trials`` random sets of the largest error of fx, fy, cx, cy (pixels).

    Returns
    -------
    str, two small tables (print it)
    """
    obj = DUCKIETOWN_BOARD.object_points()
    idx = ([0, 1, 0, 1], [0, 1, 2, 2])

    def run(n, tilt, s):
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
        med = f"{np.median(errs):10.1f}" if errs else f"{'-':>10s}"
        return med + (f" ({refused} refused)" if refused else "")

    lines = [f"noise {noise_px} px, median over {trials} random view sets of max |error| of fx, fy, cx, cy [px]",
             "", f"{'views (tilt 20-45 deg)':>24s}  error"]
    for n in view_counts:
        lines.append(f"{n:>24d}  {run(n, (20.0, 45.0), seed + n)}")
    lines += ["", f"{'tilt from camera axis':>24s}  error (10 views)"]
    for k, tilt in enumerate(tilts):
        lines.append(f"{f'{tilt[0]:g}-{tilt[1]:g} deg':>24s}  {run(10, tilt, seed + 100 + k)}")
    return "\n".join(lines)


# =========================================================================== notebook 04 figures
def distorted_board_frame() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The recorded frame where the board looks largest (its lines bend most), and the camera's truth.

    Returns
    -------
    frame : (480, 640, 3) uint8 BGR image of the recorded session (or, without a recording,
        the board rendered through the default Duckiebot lens)
    K : (3, 3) intrinsic matrix the frame was made with
    dist : (5,) distortion coefficients
    """
    ds = _datasets()
    truth = _load_truth(ds)
    if truth is None:
        from .plots import render_board_image

        K, d = dt.default_K(), dt.default_dist()
        R = cv2.Rodrigues(np.array([0.25, -0.45, 0.1]))[0]
        t = np.array([0.07, -0.02, 0.32])
        grey = render_board_image(K, d, R, t)
        return cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR), K, d
    K, d = _truth_camera(truth)
    best, best_score = None, -1.0
    for f in truth["intrinsics"]["frames"]:
        if not f.get("board_visible") or f.get("corners") is None:
            continue
        c = np.asarray(f["corners"], float).reshape(-1, 2)
        q = c[list(DUCKIETOWN_BOARD.outer_corner_indices())]
        score = 0.5 * abs(float(np.dot(q[:, 0], np.roll(q[:, 1], 1)) - np.dot(q[:, 1], np.roll(q[:, 0], 1))))
        if score > best_score:
            best, best_score = int(f["index"]), score
    if best is None:
        raise DtscalError("no recorded frame shows the whole board; the recording looks broken")
    for index, image in ds.intrinsic_frames():
        if index == best:
            return image, K, d
    raise DtscalError(f"frame {best} is missing from the recording")


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
    with the kit's Newton undistortion and ``ideal`` is sampled there. ``ideal_K`` is the
    pinhole camera of ``ideal`` (default ``K``). Pixels that see outside ``ideal`` are black.
    """
    h, w = ideal.shape[:2]
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    uv = np.column_stack([u.ravel(), v.ravel()])
    src = cam.undistort_pixels(uv, K, dist, P=K if ideal_K is None else ideal_K)
    mx = src[:, 0].reshape(h, w).astype(np.float32)
    my = src[:, 1].reshape(h, w).astype(np.float32)
    return cv2.remap(ideal, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def show_images(images: Sequence[np.ndarray], titles: Sequence[str], width: float = 4.2):
    """Images side by side (BGR or grey), titled."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(images), figsize=(width * len(images), width * 0.78), dpi=PHOTO_DPI)
    for ax, im, title in zip(np.atleast_1d(axes), images, titles):
        if im.ndim == 2:
            ax.imshow(im, cmap="gray", vmin=0, vmax=255)
        else:
            ax.imshow(cv2.cvtColor(im, cv2.COLOR_BGR2RGB))
        ax.set_title(title)
        ax.axis("off")
    fig.tight_layout()
    return fig


def plot_distortion_field(distort: Callable, K, dist, size=dt.IMAGE_SIZE, step: int = 40):
    """Where the lens moves each pixel: arrows from the pinhole position to the distorted one.

    ``distort(xy, dist)`` maps normalized to distorted normalized coordinates (the
    student's ``distort_normalized``). Colour is the displacement in pixels.
    """
    import matplotlib.pyplot as plt

    w, h = cam.as_size(size)
    u, v = np.meshgrid(np.arange(step / 2, w, step), np.arange(step / 2, h, step))
    uv = np.column_stack([u.ravel(), v.ravel()])
    xy = cam.pixel_to_normalized(uv, K)
    uv_d = cam.normalized_to_pixel(np.asarray(distort(xy, np.asarray(dist, float)), float), K)
    d = uv_d - uv
    mag = np.hypot(d[:, 0], d[:, 1])
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    q = ax.quiver(uv[:, 0], uv[:, 1], d[:, 0], -d[:, 1], mag, angles="xy", scale_units="xy", scale=1,
                  width=0.003, cmap="magma_r")
    fig.colorbar(q, ax=ax, label="displacement [px]")
    ax.plot(K[0, 2], K[1, 2], "b+", ms=12, label="principal point")
    ax.set(xlim=(0, w), ylim=(h, 0), aspect="equal", title="lens distortion: pinhole pixel -> recorded pixel")
    ax.legend(loc="lower right", fontsize=7)
    fig.tight_layout()
    return fig


def plot_undistortion_error(undistort: Callable, K, dist, size=dt.IMAGE_SIZE, step: int = 8):
    """How well an undistortion inverts the lens, over the image: yours vs OpenCV's default.

    For every pixel of a grid, the recorded (distorted) pixel is undistorted, then
    distorted again with OpenCV's model; the map shows the round-trip error in pixels (log
    scale). OpenCV's ``undistortPoints`` stops after a fixed 5 fixed-point iterations.
    """
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    from .selfcheck.distortion import opencv_distort

    w, h = cam.as_size(size)
    u, v = np.meshgrid(np.arange(0, w, step, dtype=float), np.arange(0, h, step, dtype=float))
    uv = np.column_stack([u.ravel(), v.ravel()])
    xy_d = cam.pixel_to_normalized(uv, K)
    results = {
        "yours": np.asarray(undistort(xy_d, np.asarray(dist, float)), float),
        "OpenCV undistortPoints (default)": cv2.undistortPoints(uv.reshape(-1, 1, 2), K, dist).reshape(-1, 2),
    }
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for ax, (name, xy) in zip(axes, results.items()):
        back = cam.normalized_to_pixel(opencv_distort(xy, dist), K)
        err = np.maximum(np.hypot(*(back - uv).T), 1e-12).reshape(u.shape)
        im = ax.imshow(err, extent=(0, w, h, 0), norm=LogNorm(1e-12, 100), cmap="magma")
        ax.set_title(f"{name}: worst {err.max():.2g} px")
        ax.axis("off")
    fig.colorbar(im, ax=axes, label="round-trip error [px]")
    return fig


def compare_alpha(image: np.ndarray, K, dist, maps_fn: Callable, size=None):
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


# =========================================================================== notebook 05
@dataclass
class ExtrinsicCapture:
    """The recorded extrinsic-calibration frame and what is known about it.

    Attributes
    ----------
    image : raw (distorted) BGR frame
    camera : CameraModel used to rectify (the truth intrinsics, P from alpha = 0)
    H_true : (3, 3) true homography, rectified pixel -> ground metres (for ``camera.P``)
    source : where the frame comes from
    """

    image: np.ndarray
    camera: cam.CameraModel
    H_true: np.ndarray
    source: str


def load_extrinsic_capture() -> ExtrinsicCapture:
    """The recorded extrinsic capture (``data/session/extrinsics.bag``) with its truth.

    The camera is the recording's truth with its ``P`` (the rectified image the true
    homography refers to). Without a recording the same scene is rendered on the fly by
    :mod:`dtscal_lib.synth` (a few seconds); ``source`` says which.
    """
    ds = _datasets()
    truth = _load_truth(ds)
    if truth is None:
        from . import synth

        frames, etruth = synth.extrinsic_capture(n_frames=1)
        return ExtrinsicCapture(frames[0].image, synth.synthetic_camera(), np.asarray(etruth["homography"], float),
                                "synthetic capture rendered now (no recording found)")
    frames = ds.extrinsic_frames()
    if not frames:
        raise DtscalError("the extrinsic recording holds no frame")
    K, d = _truth_camera(truth)
    h, w = frames[0].shape[:2]
    ext = truth["extrinsics"]
    camera = cam.CameraModel(K, d, (w, h), P=ext["homography_P"])
    return ExtrinsicCapture(frames[0], camera, np.asarray(ext["homography"], float),
                            f"recorded session, frame 1 of {len(frames)}")


def plot_ground_layout(ground: np.ndarray, board: Board = DUCKIETOWN_BOARD):
    """Top-down plot of ground points in the robot frame (x forward = up, y left = left)."""
    import matplotlib.pyplot as plt

    g = np.asarray(ground, float)
    fig, ax = plt.subplots(figsize=(4.2, 4.2))
    ax.plot(g[:, 1], g[:, 0], "o", ms=4, color="tab:blue")
    for k in (0, 1, board.cols):
        ax.annotate(str(k), (g[k, 1], g[k, 0]), textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.add_patch(plt.Rectangle((-0.05, -0.04), 0.1, 0.08, fill=False, lw=1.2))
    ax.arrow(0, 0, 0, 0.06, head_width=0.01, color="k")
    ax.arrow(0, 0, 0.06, 0, head_width=0.01, color="k")
    ax.text(0.0, 0.075, "x", ha="center")
    ax.text(0.08, 0.0, "y", va="center")
    ax.set(xlim=(0.2, -0.2), ylim=(-0.06, max(0.4, g[:, 0].max() + 0.05)), aspect="equal",
           xlabel="y (left) [m]", ylabel="x (forward) [m]", title="robot frame, from above")
    fig.tight_layout()
    return fig


def notebook_function(nb_name: str, func: str, nb_dir=None) -> Callable | None:
    """A student's exercise function from another notebook of the same folder, or None.

    Runs that notebook's cell tagged ``imports`` and its cells tagged ``exercise`` in a
    fresh namespace (the rest of the notebook is not run), with
    :func:`dtscal_lib.release.notebook_functions`: the student's code or the
    ``NotImplementedError`` stub. ``nb_dir`` defaults to the current folder (where Jupyter runs the
    notebook). Prints why and returns None when the function cannot be loaded.
    """
    from .release import notebook_functions

    path = Path.cwd() / nb_name if nb_dir is None else Path(nb_dir) / nb_name
    if not path.exists():
        print(f"{path.name} is not in {path.parent}; cannot load your `{func}` from it")
        return None
    try:
        return notebook_functions(path, [func])[func]
    except DtscalError as exc:
        print(f"could not load your `{func}` from {path.name}: {exc}")
        return None


def ground_error_mm(H: np.ndarray, H_true: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """|H(p) - H_true(p)| in millimetres for (N, 2) rectified pixels, (N,) float64."""
    from .ground import pixel_to_ground

    return 1000.0 * np.linalg.norm(pixel_to_ground(H, pixels) - pixel_to_ground(H_true, pixels), axis=1)


def ground_error_report(H: np.ndarray, H_true: np.ndarray, corners: np.ndarray, ground: np.ndarray,
                        x_bands=((0.15, 0.25), (0.25, 0.35), (0.35, 0.5), (0.5, 0.8)),
                        y_range=(-0.15, 0.15)) -> str:
    """How far a fitted ground homography is from the truth, in millimetres.

    Parameters
    ----------
    H, H_true : (3, 3) fitted and true homographies, rectified pixel -> ground metres
    corners : (N, 2) rectified pixels of the board's corners (ground order)
    ground : (N, 2) their ground points, metres
    x_bands : distance bands (forward, metres) over which ground points are sampled
    y_range : lateral extent of the sampled ground, metres

    Returns
    -------
    str (print it): fit residual on the corners, then the error against the truth per band
    """
    from .ground import ground_to_pixel, pixel_to_ground

    res = 1000.0 * np.linalg.norm(pixel_to_ground(H, corners) - np.asarray(ground, float), axis=1)
    lines = [f"fit residual on the {len(res)} board corners: mean {res.mean():.2f} mm, max {res.max():.2f} mm",
             "", "error against the true homography, ground sampled every 1 cm:",
             f"{'distance ahead':>18s} {'mean':>8s} {'max':>8s}"]
    for x0, x1 in x_bands:
        g = np.stack(np.meshgrid(np.arange(x0, x1 + 1e-9, 0.01), np.arange(y_range[0], y_range[1] + 1e-9, 0.01)),
                     -1).reshape(-1, 2)
        px = ground_to_pixel(H_true, g)
        e = ground_error_mm(H, H_true, px)
        lines.append(f"{f'{x0:.2f}-{x1:.2f} m':>18s} {e.mean():7.2f}mm {e.max():7.2f}mm")
    return "\n".join(lines)


def show_ground_result(rectified: np.ndarray, H: np.ndarray, corners: np.ndarray | None = None,
                       x_range=(0.1, 0.5), y_range=(-0.2, 0.2)):
    """The rectified frame with the ground grid drawn back through H, and the bird's-eye view."""
    import matplotlib.pyplot as plt

    from .ground import birdseye_view, draw_ground_grid

    grid = draw_ground_grid(rectified, H, spacing=0.05, x_range=x_range, y_range=y_range)
    if corners is not None:
        for k, (u, v) in enumerate(np.asarray(corners)):
            cv2.circle(grid, (int(round(u)), int(round(v))), 3, (0, 0, 255) if k == 0 else (255, 0, 0), -1)
    bird = birdseye_view(rectified, H, x_range=x_range, y_range=y_range, px_per_m=800)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9.5, 3.8), gridspec_kw={"width_ratios": [1.35, 1]}, dpi=PHOTO_DPI)
    a1.imshow(cv2.cvtColor(grid, cv2.COLOR_BGR2RGB))
    a1.set_title("rectified frame + 5 cm ground grid (corner 0 in red)")
    a1.axis("off")
    a2.imshow(cv2.cvtColor(bird if bird.ndim == 3 else cv2.cvtColor(bird, cv2.COLOR_GRAY2BGR), cv2.COLOR_BGR2RGB),
              extent=(y_range[1], y_range[0], x_range[0], x_range[1]))
    a2.set(xlabel="y (left) [m]", ylabel="x (forward) [m]", title="bird's-eye view")
    fig.tight_layout()
    return fig
