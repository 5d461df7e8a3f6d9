"""The headless calibration pipeline: frames of a recording (or a live camera) in, Duckietown calibration files out.

These are the functions behind ``dtscal calibrate-intrinsics`` and ``dtscal calibrate-extrinsics``: thin
drivers of :mod:`dtscal_lib.session` (where the calibration happens, and the same session the live tools
drive). Nothing here raises on a bad frame: every unusable frame is counted under a reason and skipped.
Errors are raised only when the run as a whole cannot produce a calibration, and then the message says
what to do.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from .boards import DUCKIETOWN_BOARD, Board
from .calibration import CalibrationResult
from .errors import DtscalError
from .session import (MAX_OUTLIER_SHARE, MIN_SAMPLES, OUTLIER_FACTOR, ExtrinsicSession,  # noqa: F401
                      FrameTally, IntrinsicSession, SizeGroups, calibrate_without_outlier_views, robot_from_topic,
                      robot_name)
from .sources import open_source
from .sources.headers import MAX_PIXELS, MAX_SIDE
from .validation import check_board, check_image_size, check_output_folder


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


def _robot(robot: str | None, src, writing: bool) -> str:
    """The robot of the run (:func:`~dtscal_lib.session.robot_name`); checked up front when a file is written."""
    from .calib_files import check_robot_name

    name = robot_name(getattr(src, "spec", None), src, robot)
    if not writing:
        return name or "camera"
    if not name:
        raise DtscalError("cannot tell which robot this is from the source; pass --robot NAME "
                          "(the calibration is written as camera_intrinsic/NAME.yaml)")
    return check_robot_name(name)


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
    #: the session that made it (judge, write in another format, commit)
    session: IntrinsicSession | None = field(default=None, repr=False)
    #: the session's verdict (:class:`~dtscal_lib.quality.Quality`), computed before anything was written, or
    #: why there is none (a str; the gate then refused the file unless kept anyway)
    quality: object = field(default=None, repr=False)

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
    # a live camera stops once the session is ready: the session is made (whole) right after the source
    src = _open_frames(source_spec, topic, max_seconds, lambda: session.ready())
    session = IntrinsicSession(board, model=model, skew=skew, image_size=image_size,
                               robot=_robot(robot, src, out_dir is not None), stream=src.is_stream,
                               source=src.describe())
    if out_dir is not None:
        check_output_folder(out_dir)
    for frame in (progress(src) if progress else src):
        session.offer(frame)
    session.skipped(getattr(src, "bad", {}))  # corrupt frames a live source skipped
    result = session.calibrate()
    run = IntrinsicRun(result, session.robot, session.tally(), result.n_views, session.bars(), session.source,
                       session=session, quality=session.quality())  # the verdict, before anything is written
    run.path = session.write(out_dir, keep_anyway)
    run.doubts = session.doubts
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
    #: the session that made it (write in another format, commit)
    session: ExtrinsicSession | None = field(default=None, repr=False)
    #: frames the source holds (None for a live camera): the run reads only up to the first usable one
    frames_in_source: int | None = None
    #: the camera is mounted upside down (:func:`~dtscal_lib.ground.is_upside_down`)
    upside_down: bool = False

    def frames(self) -> dict:
        """The frame counts: ``total`` read, ``used``, ``rejected`` by reason and, for a recording,
        ``in_source`` and ``not_read`` (the frames after the first usable one, which Duckietown's procedure
        does not need), so that ``total + not_read == in_source``."""
        out = self.tally.to_dict()
        if self.frames_in_source is not None:
            out["in_source"] = self.frames_in_source
            out["not_read"] = max(0, self.frames_in_source - self.tally.total)
        return out

    def to_dict(self) -> dict:
        return {
            "robot": self.robot,
            "source": self.source,
            "homography": [float(v) for v in self.H.ravel()],
            "frame_index": self.frame_index,
            "image_center_ground_m": [float(v) for v in self.image_center_ground],
            "corner_residual_mm": {"max": float(np.max(self.residual_mm)), "mean": float(np.mean(self.residual_mm))},
            "frames": self.frames(),
            "output": str(self.path) if self.path else None,
            "camera_pose": dict(self.camera_pose),
            "doubts": [str(d) for d in self.doubts],
            "upside_down": bool(self.upside_down),
        }


def calibrate_extrinsics(source_spec, intrinsics_file, *, board: Board = DUCKIETOWN_BOARD,
                         robot: str | None = None, out_dir=None, topic: str | None = None,
                         progress=None, keep_anyway: bool = False, max_seconds: float | None = None,
                         fmt: str = "classic", robot_type: str | None = None) -> ExtrinsicRun:
    """Duckietown's extrinsic procedure on the first usable frame of a source.

    ``intrinsics_file`` is a Duckietown intrinsic YAML; the homography maps pixels of the
    image rectified with that file's ``P`` to ground metres (robot frame: x forward,
    y left). ``out_dir/camera_extrinsic/<robot>.yaml`` is written when ``out_dir`` is given, in the
    classic format or (``fmt="2"``) Duckietown's version 2, if the homography describes a camera
    looking down at the ground ahead (:func:`~dtscal_lib.ground.ground_homography_doubts`);
    ``keep_anyway`` as in :func:`calibrate_intrinsics` (the rejected file in the same format).
    ``robot_type`` (``"duckiebot"``, ``"dd24"``) overrides the robot the board implies (:mod:`dtscal_lib.profiles`).
    """
    from .profiles import profile_for

    from . import calib_files

    check_board(board)
    calib = calib_files.load_intrinsics(intrinsics_file)
    check_image_size(calib.size, name=f"{intrinsics_file}: image_width x image_height",
                     hint="; give the intrinsic file of the camera that took these frames (--intrinsics)")
    src = _open_frames(source_spec, topic, max_seconds)
    session = ExtrinsicSession(calib.camera(), board, robot=_robot(robot, src, out_dir is not None),
                               keep="first", intrinsics=calib, source=src.describe(),
                               profile=profile_for(board, robot_type))
    if out_dir is not None:
        check_output_folder(out_dir)
    try:
        in_source = len(src)
    except TypeError:  # a live camera: no end
        in_source = None
    for frame in (progress(src) if progress else src):
        if session.offer(frame).added:
            break
    res = session.calibrate()
    run = ExtrinsicRun(session.robot, res.H, session.best_frame, session.tally(), np.asarray(res.residual_mm),
                       np.asarray(res.image_center_ground), session.source, camera_pose=session.camera_pose(),
                       session=session, frames_in_source=in_source, upside_down=bool(res.upside_down))
    run.path = session.write(out_dir, keep_anyway, fmt)
    run.doubts = session.doubts
    return run


__all__ = ["calibrate_intrinsics", "calibrate_extrinsics", "IntrinsicRun", "ExtrinsicRun", "FrameTally",
           "SizeGroups", "robot_from_topic", "parse_image_size", "calibrate_without_outlier_views",
           "MIN_SAMPLES"]
