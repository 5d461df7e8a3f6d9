"""The recorded session as the notebooks use it: board views, a distorted frame, the extrinsic capture.

Everything is read through :mod:`dtscal_lib.datasets` (which finds ``data/`` from the kit
checkout, the hand-out, ``DTSCAL_DATA`` or the current folder) and detected with
:mod:`dtscal_lib.detect`. Without a recording, synthetic stand-ins are made and ``source``
says so.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np

from ... import camera as cam
from ... import duckietown as dt
from ...boards import DUCKIETOWN_BOARD, Board
from ...errors import DtscalError
from .projection import render_board_image, sample_views

__all__ = ["find_corners", "board_homographies", "IntrinsicViews", "load_intrinsic_views",
           "distorted_board_frame", "ExtrinsicCapture", "load_extrinsic_capture"]


def find_corners(image: np.ndarray, board: Board = DUCKIETOWN_BOARD, thorough: bool = True) -> np.ndarray | None:
    """Inner corners of ``board`` in an image, (N, 2) float64 pixels, or None.

    The kit's fast detector (:func:`dtscal_lib.detect.detect_board`, ROS's rules); with
    ``thorough``, the still-frame detector that also runs OpenCV's full search
    (:func:`dtscal_lib.detect.detect_board_still`).
    """
    from ...detect import detect_board, detect_board_still

    det = (detect_board_still if thorough else detect_board)(image, board)
    return np.asarray(det.corners, dtype=np.float64).reshape(-1, 2) if det.found else None


def board_homographies(object_points: Sequence[np.ndarray], image_points: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Per view, OpenCV's least-squares homography board metres (X, Y) -> pixels, ``H[2, 2] = 1``.

    OpenCV (not the kit's DLT), so that notebook 03 does not depend on notebook 02's exercise.

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


def _datasets():
    from ... import datasets

    return datasets


def _load_truth() -> dict | None:
    try:
        return _datasets().load_truth()
    except (DtscalError, OSError) as exc:
        print(f"no usable recorded session ({exc}); using a synthetic stand-in")
        return None


def _truth_camera(truth: dict) -> tuple[np.ndarray, np.ndarray]:
    return cam.as_K(truth["camera"]["K"]), cam.as_dist(truth["camera"]["dist"])


def _synthetic_intrinsic_views(n_views: int, seed: int) -> IntrinsicViews:
    """Noisy synthetic detections of the Duckiebot camera (used only if no recording exists)."""
    K, d = dt.default_K(), dt.default_dist()
    obj = DUCKIETOWN_BOARD.object_points()
    rng = np.random.default_rng(seed)
    imgs, objs = [], []
    for R, t in sample_views(K, n_views, seed, max_tilt_deg=45.0, dist=d):
        imgs.append(cam.project_points(obj, R, t, K, d) + rng.normal(scale=0.15, size=(len(obj), 2)))
        objs.append(obj.copy())
    return IntrinsicViews([], imgs, objs, dt.IMAGE_SIZE, K, d, "synthetic detections (no recording found)")


def load_intrinsic_views(max_views: int = 25, n_images: int = 6, board: Board = DUCKIETOWN_BOARD,
                         step: int = 2, seed: int = 0) -> IntrinsicViews:
    """The recorded intrinsic-calibration session: frames, detected corners and the truth.

    Detects the board in every ``step``-th frame of ``data/session/intrinsics.bag`` (frames
    where it is not found are skipped) and keeps at most ``max_views`` detections, evenly
    spread over the recording.
    """
    truth = _load_truth()
    if truth is None:
        return _synthetic_intrinsic_views(max_views, seed)
    K, d = _truth_camera(truth)
    images, pts, n_frames = [], [], 0
    for _index, image in _datasets().intrinsic_frames(step=step):
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


def distorted_board_frame() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The recorded frame where the board looks largest (its lines bend most), and the camera's truth.

    Returns
    -------
    frame : (480, 640, 3) uint8 BGR image of the recorded session (or, without a recording,
        the board rendered through the default Duckiebot lens)
    K : (3, 3) intrinsic matrix the frame was made with
    dist : (5,) distortion coefficients
    """
    truth = _load_truth()
    if truth is None:
        K, d = dt.default_K(), dt.default_dist()
        R = cv2.Rodrigues(np.array([0.25, -0.45, 0.1]))[0]
        grey = render_board_image(K, d, R, np.array([0.07, -0.02, 0.32]))
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
    for index, image in _datasets().intrinsic_frames():
        if index == best:
            return image, K, d
    raise DtscalError(f"frame {best} is missing from the recording")


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

    Without a recording the same scene is rendered on the fly by :mod:`dtscal_lib.synth`
    (a few seconds); ``source`` says which.
    """
    truth = _load_truth()
    if truth is None:
        from ... import synth

        frames, etruth = synth.extrinsic_capture(n_frames=1)
        return ExtrinsicCapture(frames[0].image, synth.synthetic_camera(), np.asarray(etruth["homography"], float),
                                "synthetic capture rendered now (no recording found)")
    frames = _datasets().extrinsic_frames()
    if not frames:
        raise DtscalError("the extrinsic recording holds no frame")
    K, d = _truth_camera(truth)
    h, w = frames[0].shape[:2]
    ext = truth["extrinsics"]
    camera = cam.CameraModel(K, d, (w, h), P=ext["homography_P"])
    return ExtrinsicCapture(frames[0], camera, np.asarray(ext["homography"], float),
                            f"recorded session, frame 1 of {len(frames)}")
