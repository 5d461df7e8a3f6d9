"""The headless calibration pipeline: frames in, Duckietown calibration files out.

These are the functions behind ``dtscal calibrate-intrinsics`` and
``dtscal calibrate-extrinsics``; the Duckiebot camera notebook (06) runs the same steps frame by frame.
Nothing here raises on a bad frame: every unusable frame is counted under a reason
and skipped. Errors are raised only when the run as a whole cannot produce a
calibration, and then the message says what to do.
"""

from __future__ import annotations

import re
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable

import cv2
import numpy as np

from . import calib_files
from .boards import DUCKIETOWN_BOARD, Board
from .calibration import CalibrationResult, calibrate
from .camera import as_size
from .coverage import CoverageTracker
from .detect import detect_board
from .errors import CalibrationError, DtscalError, ImplausibleCalibrationError, Reason, opencv_message
from .plausibility import intrinsic_doubts
from .sources import Frame, open_source
from .sources.headers import MAX_PIXELS, MAX_SIDE
from .validation import check_board, check_image_size, check_output_folder

#: fewer samples than this cannot give a trustworthy calibration
MIN_SAMPLES = 3
#: a view whose own reprojection RMS exceeds this many times the median view's is an outlier
OUTLIER_FACTOR = 3.0
#: never drop more than this share of the views as outliers
MAX_OUTLIER_SHARE = 0.2


def calibrate_without_outlier_views(object_points, image_points, image_size, **kw):
    """Calibrate, drop views that fit far worse than the rest, calibrate again.

    A detection can be wrong without looking wrong: on a motion-blurred frame the
    detector may put a corner a pixel off. Such a view fits much worse than the
    others (its own RMS is several times the median view's) and biases K by more
    than the reported standard deviations admit. Views above ``OUTLIER_FACTOR`` x the
    median per-view RMS are dropped (at most ``MAX_OUTLIER_SHARE`` of them, worst first)
    and the calibration is repeated, until no view stands out.

    The repeated calibration starts from the previous solution (its camera and the kept views'
    poses: ``calibrate(..., initial=...)``), which is next to the new optimum, instead of searching
    from the closed form again; should that refinement fail, the views are calibrated from scratch.

    Returns
    -------
    (CalibrationResult, list of dropped view indices into the inputs)
    """
    keep = list(range(len(object_points)))
    dropped: list[int] = []
    result = calibrate(object_points, image_points, image_size, **kw)
    budget = int(MAX_OUTLIER_SHARE * len(keep))
    while True:
        pv = np.asarray(result.per_view_rms)
        limit = OUTLIER_FACTOR * float(np.median(pv))
        worst = [k for k in np.argsort(-pv) if pv[k] > limit]
        worst = worst[: max(0, min(budget - len(dropped), len(keep) - MIN_SAMPLES))]
        if not worst:
            return result, sorted(dropped)
        dropped += [keep[k] for k in worst]
        keep = [i for k, i in enumerate(keep) if k not in set(worst)]
        kept = [k for k in range(len(pv)) if k not in set(worst)]
        start = (result.K, result.dist, result.rvecs[kept], result.tvecs[kept])
        views = ([object_points[i] for i in keep], [image_points[i] for i in keep], image_size)
        try:
            result = calibrate(*views, initial=start, **kw)
        except CalibrationError:  # the warm start went astray: search from the closed form as the first fit did
            result = calibrate(*views, **kw)


@dataclass
class FrameTally:
    """How the frames of a run were used."""

    total: int = 0
    used: int = 0
    rejected: Counter = field(default_factory=Counter)

    def reject(self, reason: str) -> None:
        self.rejected[reason] += 1

    def to_dict(self) -> dict:
        return {"total": self.total, "used": self.used, "rejected": dict(sorted(self.rejected.items()))}


def usable_images(frames: Iterable[Frame], tally: FrameTally, size: tuple[int, int] | None = None):
    """Yield ``(frame, image)`` for frames that decode to an image (of ``size`` when given).

    Undecodable frames are counted under their own reason; with ``size`` given, frames of
    another size are counted as ``size_mismatch``. No frame fixes the size for the others:
    which size a calibration uses is decided from the frames that show the board
    (:class:`SizeGroups`).
    """
    for frame in frames:
        tally.total += 1
        if frame.error is not None or frame.image is None:
            tally.reject(frame.error.reason)
            continue
        img = frame.image
        if img.ndim < 2 or img.size == 0:
            tally.reject(Reason.EMPTY)
            continue
        if size is not None and (int(img.shape[1]), int(img.shape[0])) != tuple(size):
            tally.reject(Reason.SIZE_MISMATCH)
            continue
        yield frame, img


def parse_image_size(text: str | None) -> tuple[int, int] | None:
    """``"640x480"`` -> ``(640, 480)``; None stays None. Sizes beyond the decoding limit are refused.

    >>> parse_image_size("640x480")
    (640, 480)
    """
    if text is None:
        return None
    m = re.fullmatch(r"\s*(\d{1,6})\s*[xX]\s*(\d{1,6})\s*", str(text))
    if not m or min(int(m.group(1)), int(m.group(2))) < 1:
        raise DtscalError(f"--image-size must be WIDTHxHEIGHT in pixels, e.g. 640x480; got {text!r}")
    w, h = int(m.group(1)), int(m.group(2))
    if w > MAX_SIDE or h > MAX_SIDE or w * h > MAX_PIXELS:
        raise DtscalError(f"--image-size {w}x{h} is beyond the kit's limit of {MAX_SIDE} px a side and "
                          f"{MAX_PIXELS // 1_000_000} Mpx")
    return w, h


@dataclass
class _SizeGroup:
    tracker: CoverageTracker
    tally: FrameTally = field(default_factory=FrameTally)
    found: int = 0
    obj: list = field(default_factory=list)
    img: list = field(default_factory=list)


class SizeGroups:
    """Detections kept per image size until the calibration's size is known.

    A 1x1 thumbnail that sorts first must not decide the size of a calibration: each size
    gets its own coverage tracker and tally, and :meth:`resolve` picks the size in which the
    board was found most often (or the given one); every frame of another size is then
    counted as ``size_mismatch``.
    """

    def __init__(self, board: Board, image_size: tuple[int, int] | None = None):
        self.board = board
        self.image_size = None if image_size is None else as_size(image_size, name="image_size")
        self.groups: dict[tuple[int, int], _SizeGroup] = {}

    def ready(self) -> bool:
        """True once some size's coverage enables CALIBRATE (a live camera stops collecting then)."""
        return any(g.tracker.ready() for g in self.groups.values())

    def group(self, img: np.ndarray) -> _SizeGroup:
        size = (int(img.shape[1]), int(img.shape[0]))
        if size not in self.groups:
            self.groups[size] = _SizeGroup(CoverageTracker(self.board, size))
        return self.groups[size]

    def resolve(self, tally: FrameTally) -> tuple[tuple[int, int], _SizeGroup] | None:
        """The calibration's size and its group; merges every group's counts into ``tally``."""
        if self.image_size is not None:
            size = self.image_size
        elif self.groups:
            size = max(self.groups, key=lambda s: (self.groups[s].found, self.groups[s].tally.total))
        else:
            return None
        for other, g in self.groups.items():
            if other != size:
                tally.rejected[Reason.SIZE_MISMATCH] += g.tally.total
        chosen = self.groups.get(size)
        if chosen is None:
            return None
        tally.used += chosen.tally.used
        tally.rejected.update(chosen.tally.rejected)
        return size, chosen


def robot_from_topic(topic: str | None) -> str | None:
    """``/autobot01/camera_node/image/compressed`` -> ``autobot01``."""
    if not topic:
        return None
    m = re.match(r"^/([A-Za-z0-9_]+)/camera_node/", topic)
    return m.group(1) if m else None


def _robot_name(robot: str | None, source) -> str:
    """The robot whose file is written, checked before any work is done."""
    if robot:
        return calib_files.check_robot_name(robot)
    guess = robot_from_topic(getattr(source, "topic", None))
    if guess:
        return calib_files.check_robot_name(guess)
    raise DtscalError(
        "cannot tell which robot this is from the source; pass --robot NAME "
        "(the calibration is written as camera_intrinsic/NAME.yaml)"
    )


def _refuse_or_keep(doubts: list[str], kind: str, robot: str, out_dir, keep_anyway: bool, write) -> Path | None:
    """Refuse a calibration the kit does not believe, or (``keep_anyway``) write it as ``ROBOT.rejected.yaml``.

    ``write(rejected: bool) -> Path`` writes the file. Returns the path of the kept file
    (or ``None`` when nothing is written); raises :class:`ImplausibleCalibrationError` otherwise.
    """
    if keep_anyway:
        return write(True) if out_dir is not None else None
    listed = "".join(f"\n  - {d}" for d in doubts)
    where = f"camera_{kind}/{robot}.yaml"
    raise ImplausibleCalibrationError(
        f"refusing to write {where}: the kit does not believe this {kind} calibration:{listed}\n"
        f"Nothing was written; the previous {where} (if any) is unchanged. Record again as described, or, as an "
        f"expert, rerun with keep_anyway=True to keep the result as camera_{kind}/{robot}"
        f"{calib_files.REJECTED_SUFFIX}.yaml beside it", doubts)


@dataclass
class IntrinsicRun:
    result: CalibrationResult
    robot: str
    tally: FrameTally
    samples: int
    bars: list
    source: str
    path: Path | None = None
    #: why the kit does not believe the result (kept with keep_anyway); empty when plausible
    doubts: list = field(default_factory=list)

    def to_dict(self) -> dict:
        out = self.result.to_dict()
        out.update(
            robot=self.robot,
            source=self.source,
            samples_used=self.samples,
            frames=self.tally.to_dict(),
            coverage={b.name: round(float(b.progress), 4) for b in self.bars},
            output=str(self.path) if self.path else None,
            doubts=[str(d) for d in self.doubts],
        )
        return out


def _open_frames(source_spec, topic, max_seconds=None, done=None):
    """A recording (:func:`open_source`), or a live camera (``ros:``, ``device:``, URL) read until ``done()``."""
    from .sources.live import LiveFrames, is_live_spec

    if is_live_spec(source_spec):
        return LiveFrames(source_spec, topic=topic, max_seconds=max_seconds, done=done)
    return open_source(source_spec, topic=topic)


def calibrate_intrinsics(source_spec, *, board: Board = DUCKIETOWN_BOARD, model: str = "plumb_bob",
                         skew: bool = False, robot: str | None = None, out_dir=None, topic: str | None = None,
                         progress: Callable[[Iterable], Iterable] | None = None,
                         keep_anyway: bool = False, max_seconds: float | None = None,
                         image_size: tuple[int, int] | None = None) -> IntrinsicRun:
    """Detect the board in every frame of a source, select samples, calibrate, write the YAML.

    Streams (bags, videos) use ROS's coverage rule: a detection becomes a sample only when
    its (X, Y, Size, Skew) is more than 0.2 (L1) from every sample so far. A folder of
    still images uses every view in which the board is found.

    Parameters
    ----------
    source_spec : path of a ROS 1 bag, a video, a folder or a glob of images
    out_dir : the ``calibrations`` folder; ``out_dir/camera_intrinsic/<robot>.yaml`` is written.
        ``None`` writes nothing.
    progress : optional wrapper around the frame iterator (e.g. tqdm)
    max_seconds : live cameras only: stop collecting after this long (they stop anyway once
        the coverage rule enables CALIBRATE)
    keep_anyway : when the result fails :func:`~dtscal_lib.plausibility.intrinsic_doubts`, write it as
        ``<robot>.rejected.yaml`` and return it with ``run.doubts`` instead of raising
        :class:`~dtscal_lib.errors.ImplausibleCalibrationError` (``<robot>.yaml`` is never replaced by it)
    image_size : (width, height) of the frames to calibrate; by default the size of the
        frames in which the board is found most often. Frames of other sizes are counted as
        ``size_mismatch`` and skipped.
    """
    check_board(board)
    groups = SizeGroups(board, image_size)
    src = _open_frames(source_spec, topic, max_seconds, groups.ready)
    robot_name = (_robot_name(robot, src) if out_dir is not None
                  else (robot or robot_from_topic(getattr(src, "topic", None)) or "camera"))
    if out_dir is not None:
        check_output_folder(out_dir)
    tally = FrameTally()
    frames = progress(src) if progress else src
    for frame, img in usable_images(frames, tally):
        group = groups.group(img)
        group.tally.total += 1
        if groups.image_size not in (None, group.tracker.image_size):
            continue  # not the requested size: no detection, counted as size_mismatch at the end
        try:
            det = detect_board(img, board)
        except DtscalError as exc:  # a frame the detector cannot take: count it, go on
            group.tally.reject(exc.reason or Reason.BAD_FRAME)
            continue
        except cv2.error:  # OpenCV choking on one odd frame must not end the run
            group.tally.reject(Reason.DETECTOR_ERROR)
            continue
        if not det.found:
            group.tally.reject(det.reason or Reason.NO_BOARD)
            continue
        group.found += 1
        if src.is_stream:
            if group.tracker.offer(det):
                group.tally.used += 1
            else:
                group.tally.reject(Reason.NOT_NEW_COVERAGE)
        else:
            group.tracker.offer(det)  # keeps the bars meaningful for stills too
            group.obj.append(board.object_points())
            group.img.append(det.corners)
            group.tally.used += 1
    tally.rejected.update(getattr(src, "bad", {}))  # corrupt frames a live source skipped
    resolved = groups.resolve(tally)
    if resolved is None and groups.groups:
        seen = ", ".join(f"{w}x{h}" for w, h in groups.groups)
        raise DtscalError(f"{src.describe()}: no frame has the requested image size {image_size[0]}x{image_size[1]} "
                          f"(sizes found: {seen}); pass the size of the camera's frames")
    if resolved is None:
        raise DtscalError(f"{src.describe()}: no readable frame ({tally.total} frames, rejected: "
                          f"{dict(tally.rejected) or 'none'}); check the path and the topic")
    size, group = resolved
    tracker = group.tracker
    if src.is_stream:
        obj, imgp = tracker.object_and_image_points()
    else:
        obj, imgp = group.obj, group.img
    if len(obj) < MIN_SAMPLES:
        raise CalibrationError(
            f"only {len(obj)} usable view(s) of the {board.describe()} board in {src.describe()} "
            f"({tally.total} frames; rejected: {dict(tally.rejected)}). Calibration needs at least "
            f"{MIN_SAMPLES} views at different positions and tilts: check --board/--square, and show the "
            "whole board (not touching the image border) at several places and angles"
        )
    result, dropped = calibrate_without_outlier_views(obj, imgp, size, model=model, skew=skew)
    if dropped:
        tally.used -= len(dropped)
        tally.rejected[Reason.OUTLIER_VIEW] += len(dropped)
    run = IntrinsicRun(result, robot_name, tally, len(obj) - len(dropped), tracker.bars(), src.describe())
    calib = calib_files.IntrinsicCalibration.from_camera(result.camera(), camera_name=f"/{robot_name}/camera_node")
    gone = set(dropped)
    run.doubts = intrinsic_doubts(result, [p for i, p in enumerate(imgp) if i not in gone])
    if run.doubts:
        run.path = _refuse_or_keep(run.doubts, "intrinsic", robot_name, out_dir, keep_anyway,
                                   lambda rejected: calib_files.save_intrinsics(calib, out_dir, robot_name,
                                                                                rejected=rejected))
    elif out_dir is not None:
        run.path = calib_files.save_intrinsics(calib, out_dir, robot_name)
    return run


@dataclass
class ExtrinsicRun:
    robot: str
    H: np.ndarray
    frame_index: int
    tally: FrameTally
    residual_mm: np.ndarray
    image_center_ground: np.ndarray
    source: str
    path: Path | None = None
    #: the camera's height and pitch recovered from H (:func:`~dtscal_lib.ground.camera_pose_from_homography`)
    camera_pose: dict = field(default_factory=dict)
    #: why the kit does not believe the homography (kept with keep_anyway); empty when plausible
    doubts: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return {
            "robot": self.robot,
            "source": self.source,
            "homography": [float(v) for v in self.H.ravel()],
            "frame_index": self.frame_index,
            "image_center_ground_m": [float(v) for v in self.image_center_ground],
            "corner_residual_mm": {"max": float(np.max(self.residual_mm)), "mean": float(np.mean(self.residual_mm))},
            "frames": self.tally.to_dict(),
            "output": str(self.path) if self.path else None,
            "camera_pose": dict(self.camera_pose),
            "doubts": [str(d) for d in self.doubts],
        }


def calibrate_extrinsics(source_spec, intrinsics_file, *, board: Board = DUCKIETOWN_BOARD,
                         robot: str | None = None, out_dir=None, topic: str | None = None,
                         progress=None, keep_anyway: bool = False, max_seconds: float | None = None) -> ExtrinsicRun:
    """Duckietown's extrinsic procedure on the first usable frame of a source.

    ``intrinsics_file`` is a Duckietown intrinsic YAML; the homography maps pixels of the
    image rectified with that file's ``P`` to ground metres (robot frame: x forward,
    y left). ``out_dir/camera_extrinsic/<robot>.yaml`` is written when ``out_dir`` is given, if the
    homography describes a camera looking down at the ground ahead
    (:func:`~dtscal_lib.ground.ground_homography_doubts`); ``keep_anyway`` as in :func:`calibrate_intrinsics`.
    """
    from .ground import extrinsics_from_image as fit_on_image
    from .ground import camera_pose_from_homography, ground_homography_doubts

    check_board(board)
    calib = calib_files.load_intrinsics(intrinsics_file)
    check_image_size(calib.size, name=f"{intrinsics_file}: image_width x image_height",
                     hint="; give the intrinsic file of the camera that took these frames (--intrinsics)")
    camera = calib.camera()
    src = _open_frames(source_spec, topic, max_seconds)
    robot_name = (_robot_name(robot, src) if out_dir is not None
                  else (robot or robot_from_topic(getattr(src, "topic", None)) or "camera"))
    if out_dir is not None:
        check_output_folder(out_dir)
    tally = FrameTally()
    frames = progress(src) if progress else src
    last_error = None
    for frame, img in usable_images(frames, tally):
        try:
            res = fit_on_image(img, camera, board)
        except DtscalError as exc:  # counted under the frame's own reason (size, NaN, board, homography)
            tally.reject(exc.reason or Reason.HOMOGRAPHY_FAILED)
            last_error = exc
            continue
        except cv2.error as exc:  # OpenCV choking on one odd frame must not end the run
            tally.reject(Reason.DETECTOR_ERROR)
            last_error = opencv_message(exc)
            continue
        tally.used += 1
        run = ExtrinsicRun(robot_name, res.H, frame.index, tally, np.asarray(res.residual_mm),
                           np.asarray(res.image_center_ground), src.describe(),
                           camera_pose=camera_pose_from_homography(res.H, camera.P[:, :3]),
                           doubts=ground_homography_doubts(res.H, camera.P[:, :3], board=board,
                                                           pattern_contrast=res.pattern_contrast))
        if run.doubts:
            run.path = _refuse_or_keep(run.doubts, "extrinsic", robot_name, out_dir, keep_anyway,
                                       lambda rejected, H=res.H: calib_files.save_extrinsics(H, out_dir, robot_name,
                                                                                    rejected=rejected))
        elif out_dir is not None:
            run.path = calib_files.save_extrinsics(res.H, out_dir, robot_name)
        return run
    raise CalibrationError(
        f"no frame of {src.describe()} gave a ground homography ({tally.total} frames; rejected: "
        f"{dict(tally.rejected)})" + (f"; last problem: {last_error}" if last_error else "")
        + ". Place the robot on the board as in the Duckietown procedure, with the whole board in view"
    )


__all__ = ["calibrate_intrinsics", "calibrate_extrinsics", "IntrinsicRun", "ExtrinsicRun", "FrameTally",
           "usable_images", "SizeGroups", "robot_from_topic"]
