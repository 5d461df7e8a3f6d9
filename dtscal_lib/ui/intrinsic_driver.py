"""The live intrinsic calibrator without its widgets: what happens to a frame and what each button does.

:class:`IntrinsicDriver` drives an :class:`~dtscal_lib.session.IntrinsicSession` (the one the command
line drives) from a live source: it checks and offers each frame, keeps the thumbnails and the counts of
skipped frames, runs CALIBRATE off the frame loop (:class:`~dtscal_lib.ui.background.BackgroundCalibration`)
and does COMMIT, SAVE and LOAD, each answering with a message ``(text, kind)``. It holds no widget:
:class:`~dtscal_lib.ui.intrinsic.LiveCalibrator` adds them (and shows what this class returns), so the
whole tool can be driven, and tested, without a browser.
"""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import calib_files
from ..boards import DUCKIETOWN_BOARD, Board
from ..camera import CameraModel
from ..coverage import CoverageTracker
from ..errors import DtscalError, ImplausibleCalibrationError, Reason
from ..session import MIN_SAMPLES, IntrinsicSession, robot_name
from ..sources.live import open_live
from . import render
from .archive import load_session, save_session
from .background import BackgroundCalibration, PreviewMaps
from .driver import LoopDriver, dtps_link_of
from .frameloop import FrameLoop

#: what the tool says of its frames when the source stops (every sample is kept)
KEPT = "Every sample is kept"


@dataclass
class Taken:
    """One frame the calibrator used: its detection, whether it became a sample, the coverage after it."""

    image: np.ndarray
    detection: object
    added: bool
    n: int
    ready: bool
    bars: list | None
    arrival: float


class IntrinsicDriver(LoopDriver):
    """The session, the work off the frame loop and the actions of the live calibrator (no widgets).

    The widget class overrides the hooks ``_calibrated``, ``_failed``, ``_verdict`` and ``_calibrate_ended``
    (called from the calibration's thread) to show what happened; here they keep the state only.
    """

    def __init__(self, source, *, board: Board = DUCKIETOWN_BOARD, robot: str | None = None,
                 model: str = "plumb_bob", realtime: bool = True, loop: bool = False):
        self.board = board
        self.model = model
        self.spec = str(getattr(source, "spec", source))
        self.source = open_live(source, realtime=realtime, loop=loop) if isinstance(source, (str, Path)) else source
        #: where the calibration happens (the same session the command line drives)
        self.session = IntrinsicSession(board, model=model, first_size_wins=True, source=self.spec,
                                        robot=robot_name(self.spec, self.source, robot) or "camera")
        self.thumbs: list[bytes] = []
        self.quality = None
        self._calibrating_from = 0
        self.bad: Counter = Counter()
        self.frames_seen = 0
        self.last_frame = None
        self.state = "connecting"
        self._lock = self.session.lock
        # CALIBRATE runs off the frame loop, its solver in a helper process (solver.py: in a thread, it would
        # stall the image); the preview's maps are made in a helper thread
        self.background = BackgroundCalibration(self.session, on_result=self._calibrated, on_error=self._failed,
                                                on_verdict=self._verdict, on_end=self._calibrate_ended)
        self._preview = PreviewMaps(self._lock)
        self.loop = FrameLoop(self.source, self._on_frame, self._on_status)  # started by the widgets

    # ------------------------------------------------------------------ state: the session's and the background's
    robot = property(lambda self: self.session.robot, lambda self, name: setattr(self.session, "robot", name))
    tracker = property(lambda self: self.session.tracker, lambda self, t: setattr(self.session, "tracker", t),
                       doc="the coverage (samples, bars) of the session")
    result = property(lambda self: self.session.result, doc="the CalibrationResult, None before CALIBRATE")
    dropped = property(lambda self: self.session.dropped, doc="views dropped as outliers by the last CALIBRATE")
    calibrating = property(lambda self: self.background.busy)
    calibrate_error = property(lambda self: self.background.error)
    calibrate_seconds = property(lambda self: self.background.seconds)
    _solver = property(lambda self: self.background.solver)
    _preview_key = property(lambda self: self._preview.key)
    _preview_maps = property(lambda self: self._preview.maps)

    @property
    def samples(self):
        return [] if self.tracker is None else list(self.tracker.samples)

    def camera(self) -> CameraModel | None:
        """The calibrated camera (``P`` with alpha 0, as ROS sets it), or None before CALIBRATE."""
        return self.session.camera

    def calibration(self) -> calib_files.IntrinsicCalibration | None:
        """The content of ``camera_intrinsic/<ROBOT>.yaml`` (None before CALIBRATE)."""
        return self.session.calibration()

    # ------------------------------------------------------------------ frames
    def _on_status(self, st) -> None:
        self.state = st.state

    def _on_frame(self, frame) -> bool | None:
        return None if self.take(frame) is not None else False

    def take(self, frame) -> Taken | None:
        """Offer one frame to the session; None (counted in ``bad``) when the calibrator cannot use it."""
        arrival = getattr(frame, "arrival", None) or time.time()  # frames made by hand have none
        img = frame.image
        if img is None or img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
            return self._skip("odd_frame")
        offer = self.session.offer(frame)
        if offer.reason == Reason.SIZE_MISMATCH:
            return self._skip("size_mismatch")
        if offer.detection is None:  # the detector could not take the frame
            return self._skip("detector_error")
        det, added = offer.detection, offer.added
        with self._lock:
            if added:
                self.thumbs.append(render.thumbnail(img, det.corners))
            n = len(self.tracker.samples)
            ready = self.tracker.ready()
            bars = self.tracker.bars() if added else None
        if added and n >= MIN_SAMPLES:
            self.prepare_calibration()
        self.frames_seen += 1
        self.last_frame = img
        return Taken(img, det, added, n, ready and not self.background.busy and n >= MIN_SAMPLES, bars, arrival)

    def _skip(self, reason: str) -> None:
        self.bad[reason] += 1
        return None

    def skipped_text(self) -> str:
        """``samples: N; frames skipped: REASON COUNT, ...`` (shown under the bars after a skipped frame)."""
        return f"samples: {len(self.samples)}; frames skipped: " + ", ".join(
            f"{k} {v}" for k, v in sorted(self.bad.items()))

    def drop(self, i: int):
        """Forget sample ``i`` (0-based) and its thumbnail; the new ``(bars, n)``, or None if there is none."""
        with self._lock:
            if self.tracker is None or not 0 <= i < len(self.tracker.samples):
                return None
            del self.tracker.samples[i]
            del self.thumbs[i]
            return self.tracker.bars(), len(self.tracker.samples)

    # ------------------------------------------------------------------ CALIBRATE
    def prepare_calibration(self, wait: float = 0.0) -> bool:
        """Start the calibration process ahead of CALIBRATE (done by itself at 3 samples); True when ready."""
        return self.background.prepare(wait)

    def start_calibration(self, on_start=None):
        """CALIBRATE in the background (the job already running, if one is); ``on_start(n_samples)`` when it starts."""
        with self._lock:
            if not self.background.busy:
                self._calibrating_from = len(self.samples)
                if on_start is not None:
                    on_start(self._calibrating_from)
            return self.background.start(self.prepare_calibration)

    def _calibrated(self, result) -> None:
        with self._lock:
            self.quality = None

    def _failed(self, message: str) -> None:
        pass

    def _verdict(self, result, quality) -> None:
        with self._lock:
            self.quality = quality

    def _calibrate_ended(self) -> None:
        pass

    def set_model(self, model: str) -> None:
        """The lens model of the next CALIBRATE (one of :data:`dtscal_lib.camera.DIST_MODELS`)."""
        from ..camera import DIST_MODELS

        if model not in DIST_MODELS:
            raise DtscalError(f"lens model must be one of {DIST_MODELS}, got {model!r}")
        self.model = self.session.model = model

    # ------------------------------------------------------------------ the new calibration against the robot's file
    def robot_file(self, folder) -> tuple[calib_files.IntrinsicCalibration, str]:
        """The robot's current intrinsic file: ``folder/camera_intrinsic/<ROBOT>.yaml``, else the folder's
        ``default.yaml``, else Duckietown's factory calibration (what a robot without its own file uses)."""
        for name in (self.robot, "default"):
            try:
                path = calib_files.intrinsic_path(folder, name)
            except DtscalError:  # not a robot name a file can have
                continue
            if path.exists():
                return calib_files.load_intrinsics(path), str(path)
        from .. import duckietown as dt

        return (calib_files.IntrinsicCalibration.from_dict(dt.DEFAULT_INTRINSICS, "Duckietown's default"),
                "Duckietown's factory default.yaml")

    def compare_with_robot(self, folder) -> str | None:
        """One sentence: how far the new calibration is from the robot's current file (mrcal's projection
        difference after the aligning rotation, :mod:`dtscal_lib.compare`), judged by the new one's uncertainty and,
        when the robot's file carries one (written by the kit), by that file's too; None before CALIBRATE."""
        from ..compare import projection_difference

        result = self.result
        if result is None:
            return None
        try:
            current, where = self.robot_file(folder)
            # the file itself when there is one: a file the kit wrote carries its σ (dtscal_lib.file_uncertainty)
            comp = projection_difference(where if Path(where).is_file() else current, result, names=(where, "new"))
        except DtscalError as exc:
            return f"Cannot compare with the robot's file: {exc}"
        other = "the robot's file (" + where + ")"
        return f"The new calibration {comp.sentence(other)}."

    # ------------------------------------------------------------------ COMMIT, SAVE, LOAD: (message, kind)
    def commit_to(self, folder: str, *, keep_anyway: bool, target: str) -> tuple[str, str]:
        """COMMIT through the session's gate: the folder's ``camera_intrinsic/<ROBOT>.yaml``, then (``target``
        ``"dtps"``) the robot's key-value store or (``"ros"``) its ``set_camera_info``. Refused, kept anyway or
        failed: the message says so."""
        if self.result is None:
            return "nothing to commit yet: CALIBRATE first", "error"
        try:
            path = self.session.write(folder, keep_anyway=keep_anyway)
            if self.session.doubts:
                return (f"COMMIT: kept as {path} beside the robot's file, against the kit's doubts: "
                        + "; ".join(map(str, self.session.doubts)) + ". It is not sent to the robot.", "error")
            if target == "folder":
                return f"COMMIT: wrote {path} (the previous file, if any, is kept as .bak)", "ok"
            answer = self.session.commit(master_uri=getattr(self.source, "master", None),
                                         dtps=dtps_link_of(self.source, self.robot) if target == "dtps" else None)
            return f"COMMIT to {self.robot}: {answer} (local copy: {path})", "ok"
        except ImplausibleCalibrationError as exc:
            doubts = "".join(f"<br>- {d}" for d in exc.doubts)
            return (f"COMMIT refused: the kit does not believe this calibration, nothing was written and nothing "
                    f"sent:{doubts}<br>Collect more varied samples and CALIBRATE again, or, as an expert, tick "
                    f"\"keep anyway\" to keep it as {self.robot}{calib_files.REJECTED_SUFFIX}.yaml beside the "
                    "robot's file.", "error")
        except (DtscalError, OSError) as exc:
            return f"COMMIT failed: {exc}. The previous calibration is unchanged; SAVE still keeps this one.", "error"

    def save_to(self, path) -> tuple[str, str]:
        """SAVE: the samples (and the calibration, if any) in one zip archive."""
        path = Path(path or f"{self.robot}_session.zip")
        if self.tracker is None:
            return "nothing to save yet: no frame has arrived", "error"
        with self._lock:
            samples = list(self.tracker.samples)
        try:
            out = save_session(path, board=self.board, image_size=self.tracker.image_size, robot=self.robot,
                               samples=samples, calibration=self.calibration())
        except DtscalError as exc:
            return f"SAVE failed: {exc}", "error"
        return (f"SAVE: {len(samples)} samples" + (" and the calibration" if self.result else "")
                + f" in {out}", "ok")

    def load_from(self, path) -> tuple[str, str, tuple | None]:
        """LOAD: the samples of a SAVE archive replace the session's; ``(text, kind, (bars, n) or None)``."""
        try:
            arch = load_session(path)
        except DtscalError as exc:
            return f"LOAD failed: {exc}", "error", None
        if arch.board != self.board:
            return (f"LOAD failed: the archive is for a {arch.board.describe()} board, this calibrator uses "
                    f"{self.board.describe()}", "error", None)
        with self._lock:
            if self.tracker is None or self.tracker.image_size != arch.image_size:
                self.tracker = CoverageTracker(self.board, arch.image_size)
            self.tracker.samples = list(arch.samples)
            self.thumbs = [render.outline_thumb(s.corners, arch.image_size) for s in arch.samples]
            bars, n = self.tracker.bars(), len(arch.samples)
        return f"loaded {n} samples from {path}; CALIBRATE to recalibrate", "ok", (bars, n)

    def reconnect_to(self) -> tuple[str, str]:
        """RECONNECT: re-open the source; samples and calibration are kept."""
        return self._reconnect(f"; {len(self.samples)} samples kept")

    def close(self) -> None:
        """Stop the frame loop, close the source and end the calibration process."""
        self.loop.close()
        self.background.close()
