"""The live extrinsic tool without its widgets: what happens to a frame and what SAVE does.

:class:`ExtrinsicDriver` drives an :class:`~dtscal_lib.session.ExtrinsicSession` (the one ``dtscal
calibrate-extrinsics`` drives), keeping the best fit: it takes the intrinsic calibration (a camera, a
file, or a live calibrator's as soon as it has one), rectifies each frame with maps made once per
calibration, offers it to the session and counts the frames it cannot use; SAVE goes through the
session's gate and answers with a message ``(text, kind)``. It holds no widget:
:class:`~dtscal_lib.ui.extrinsic.LiveExtrinsics` adds them.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import calib_files
from ..boards import DUCKIETOWN_BOARD, Board, ground_points
from ..camera import CameraModel, rectify_image
from ..errors import DtscalError, ImplausibleCalibrationError, Reason
from ..ground import UPSIDE_DOWN_SAID
from ..session import ExtrinsicSession, robot_name
from ..sources.live import open_live
from .driver import LoopDriver, dtps_link_of
from .frameloop import FrameLoop
from .render import rectification_maps_fast

#: what the tool says of its frames when the source stops
KEPT = "The best fit is kept"


class _MapsCamera(CameraModel):
    """A camera whose rectification maps are made once, by OpenCV (see
    :func:`~dtscal_lib.ui.render.rectification_maps_fast`): :func:`extrinsics_from_image` asks
    for them on every frame, and the kit's numpy maps cost ~0.1 s of CPU each time."""

    def rectification_maps(self, new_K=None, size=None):
        if new_K is not None or size is not None:
            return super().rectification_maps(new_K, size)
        maps = self.__dict__.get("_maps")
        if maps is None:
            maps = rectification_maps_fast(self)
            object.__setattr__(self, "_maps", maps)
        return maps


@dataclass
class Fitted:
    """One frame for the views: the rectified image (the raw one while waiting for intrinsics), the fit on
    it (None: ``reason``), the best fit so far and its frame. ``reason is None``: waiting for intrinsics."""

    image: np.ndarray
    fit: object
    best: object
    best_frame: int
    reason: str | None
    arrival: float


class ExtrinsicDriver(LoopDriver):
    """The session, the intrinsics, the frames' bookkeeping and SAVE of the live extrinsic tool (no widgets)."""

    #: while there is no intrinsic calibration the tool idles: one camera frame per this many seconds
    WAITING_PERIOD = 1.0

    def __init__(self, source, intrinsics, *, board: Board = DUCKIETOWN_BOARD, robot: str | None = None,
                 realtime: bool = True, loop: bool = True, robot_type: str | None = None):
        from ..profiles import profile_for

        self.board = board
        self.spec = str(getattr(source, "spec", source))
        self.source = open_live(source, realtime=realtime, loop=loop) if isinstance(source, (str, Path)) else source
        if isinstance(intrinsics, (str, Path)):
            intrinsics = calib_files.load_intrinsics(intrinsics).camera()
        self._intrinsics = intrinsics
        #: where the fits happen (the session the command line drives), keeping the best
        self.session = ExtrinsicSession(None, board, keep="best", source=self.spec,
                                        robot=robot_name(self.spec, self.source, robot) or "camera",
                                        profile=profile_for(board, robot_type))
        prof = self.session.profile  # the robot the board implies (dtscal_lib.profiles)
        self.ground_true = ground_points(board, prof.near_row_x, prof.right_column_y)
        self.current = None
        self.reason = ""
        self.bad: Counter = Counter()
        self.frames_seen = 0
        self.state = "connecting"
        self._lock = threading.RLock()
        self._maps_for = None
        self._maps = None
        self._waiting_shown = 0.0
        self._closed = threading.Event()
        self.loop = FrameLoop(self.source, self._on_frame, self._on_status)  # started by start()

    # ------------------------------------------------------------------ the session's state
    robot = property(lambda self: self.session.robot, lambda self, name: setattr(self.session, "robot", name))
    best = property(lambda self: self.session.best,
                    doc="the best fit so far (:class:`~dtscal_lib.ground.ExtrinsicResult`), or None")
    best_frame = property(lambda self: self.session.best_frame)

    def camera(self) -> CameraModel | None:
        """The intrinsic calibration in use (None while a live calibrator has none yet)."""
        src = self._intrinsics
        if isinstance(src, CameraModel) or src is None:
            return src
        return src.camera()

    def start(self, on_wait=None) -> None:
        """Start the frame loop, or, while there is no intrinsic calibration, once there is one (``on_wait()``
        is called then): until then the tool waits without receiving or processing frames (no CPU)."""
        if self.camera() is not None:
            self.loop.start()
            return
        if on_wait is not None:
            on_wait()

        def wait():
            while not self._closed.wait(0.2):
                if self.camera() is not None:
                    self.loop.start()
                    return

        threading.Thread(target=wait, daemon=True, name="dtscal-extrinsic-wait").start()

    def _rectify(self, img, cam: CameraModel) -> tuple[np.ndarray, CameraModel]:
        """The rectified frame, and the camera with its maps made once (used for the fit too)."""
        old = self._maps_for
        same = (old is not None and np.array_equal(old.K, cam.K) and np.array_equal(old.dist, cam.dist)
                and np.array_equal(old.P, cam.P) and old.size == cam.size)
        if not same:
            fast = _MapsCamera(cam.K, cam.dist, cam.size, cam.model, cam.P)
            self._maps = fast.rectification_maps()
            if old is not None:  # a new intrinsic calibration: fits made with the old one no longer count
                self.reset_best()
            self._maps_for = self.session.camera = fast
        return rectify_image(img, self._maps), self._maps_for

    # ------------------------------------------------------------------ frames
    def _on_status(self, st) -> None:
        self.state = st.state

    def _on_frame(self, frame) -> bool | None:
        return None if self.take(frame) is not None else False

    def take(self, frame) -> Fitted | None:
        """Fit one frame through the session; None (counted in ``bad``, or idle) when there is nothing to show."""
        arrival = getattr(frame, "arrival", None) or time.time()  # frames made by hand have none
        img = frame.image
        if img is None or img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
            self.bad["odd_frame"] += 1
            return None
        self.frames_seen += 1
        cam = self.camera()
        if cam is None:  # idle: show the camera now and then, and let the loop rest (no CPU burnt)
            now = time.monotonic()
            if now - self._waiting_shown < self.WAITING_PERIOD:
                self.loop.idle(self.WAITING_PERIOD / 4)
                return None
            self._waiting_shown = now  # the caller shows it, then lets the loop rest
            return Fitted(img, None, None, -1, None, arrival)
        if (img.shape[1], img.shape[0]) != cam.size:
            self.bad["size_mismatch"] += 1
            return None
        rect, cam = self._rectify(img, cam)
        offer = self.session.offer(frame, camera=cam)
        res = offer.detection
        if res is None and offer.reason == Reason.DETECTOR_ERROR:
            self.reason = "OpenCV could not process this frame"
            self.bad["detector_error"] += 1
        elif res is None:
            self.reason = str(self.session.last_error)
        with self._lock:
            self.current = res
            best = self.best
        return Fitted(rect, res, best, self.best_frame, "" if res is not None else self.reason, arrival)

    # ------------------------------------------------------------------ SAVE, RESET, RECONNECT
    def save_to(self, folder: str, *, keep_anyway: bool, fmt: str, target: str) -> tuple[str, str]:
        """SAVE through the session's gate: the best homography as ``camera_extrinsic/<ROBOT>.yaml`` in the
        folder (``fmt`` classic or ``"2"``), then (``target`` ``"robot"``) the upload to the robot's file server or
        (``"dtps"``) its key-value store."""
        with self._lock:
            best, frame = self.best, self.best_frame
        if best is None:
            return "nothing to save yet: no frame gave a fit", "error"
        try:
            path = self.session.write(folder, keep_anyway=keep_anyway, fmt=fmt)
            text = f"SAVE: wrote {path} (best fit, frame {frame}, mean error {np.mean(best.residual_mm):.2f} mm)"
            if best.upside_down:
                text += f"; {UPSIDE_DOWN_SAID}"
            if self.session.doubts:
                return (text + "; kept against the kit's doubts: " + "; ".join(map(str, self.session.doubts))
                        + ". It is not sent to the robot.", "error")
            if target in ("robot", "dtps"):
                text += "; " + self.session.commit(master_uri=getattr(self.source, "master", None), fmt=fmt,
                                                   dtps=dtps_link_of(self.source, self.robot)
                                                   if target == "dtps" else None)
        except ImplausibleCalibrationError as exc:
            doubts = "".join(f"<br>- {d}" for d in exc.doubts)
            return (f"SAVE refused: the kit does not believe this homography, nothing was written:{doubts}"
                    "<br>Place the robot on the board as in the Duckietown procedure, or, as an expert, "
                    f"tick \"keep anyway\" to keep it as {self.robot}{calib_files.REJECTED_SUFFIX}.yaml "
                    "beside the robot's file.", "error")
        except (DtscalError, OSError) as exc:
            return f"SAVE failed: {exc}. The previous file is unchanged.", "error"
        return text, "ok"

    def reset_best(self) -> None:
        """Forget the best fit (e.g. after moving the robot on the board)."""
        self.session.forget()

    def reconnect_to(self) -> tuple[str, str]:
        """RECONNECT: re-open the source."""
        return self._reconnect()

    def close(self) -> None:
        self._closed.set()
        self.loop.close()
