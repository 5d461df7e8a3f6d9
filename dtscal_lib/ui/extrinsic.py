"""The live extrinsic tool: Duckietown's ground calibration with a live view and a validation view.

With the robot standing on the board (Duckietown's placement, see :mod:`dtscal_lib.boards`),
every frame is rectified with the intrinsic calibration, the board detected and the ground
homography fitted (:func:`dtscal_lib.ground.extrinsics_from_image`). The tool shows

* the rectified camera view with the detected corners,
* a top view of the board: where the fitted homography puts each detected corner against
  its true ground position (errors drawn magnified), and the fit error in millimetres now and
  the best so far,
* a validation view with the best homography: the ground grid drawn back on the live image
  and a bird's-eye view of the scene.

The fits happen in a :class:`dtscal_lib.session.ExtrinsicSession` (the one ``dtscal
calibrate-extrinsics`` drives), keeping the best. SAVE writes the *best* homography as
``camera_extrinsic/<ROBOT>.yaml`` into the calibration folder (Duckietown's classic ``homography:``
file, or version 2) through the session's gate: a homography the kit does not believe is refused
as by the command line ("keep anyway" writes ``ROBOT.rejected.yaml`` beside, never uploaded).

Examples
--------
>>> tool = LiveExtrinsics("data/session/extrinsics.bag", intrinsics=calibrator)   # doctest: +SKIP
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from pathlib import Path

import cv2
import numpy as np

from .. import calib_files
from ..boards import DUCKIETOWN_BOARD, Board, ground_points
from ..camera import CameraModel, rectify_image
from ..errors import DtscalError, ImplausibleCalibrationError, Reason
from ..ground import birdseye_view, draw_ground_grid, pixel_to_ground
from ..session import ExtrinsicSession, robot_name
from ..sources.live import open_live
from . import render
from .frameloop import DisplayPacer, FrameLoop, ack_widgets
from .render import rectification_maps_fast


class _MapsCamera(CameraModel):
    """A camera whose rectification maps are made once, by OpenCV (see
    :func:`~dtscal_lib.ui.intrinsic.rectification_maps_fast`): :func:`extrinsics_from_image` asks
    for them on every frame, and the kit's numpy maps cost ~0.1 s of CPU each time."""

    def rectification_maps(self, new_K=None, size=None):
        if new_K is not None or size is not None:
            return super().rectification_maps(new_K, size)
        maps = self.__dict__.get("_maps")
        if maps is None:
            maps = rectification_maps_fast(self)
            object.__setattr__(self, "_maps", maps)
        return maps


class LiveExtrinsics:
    """Live ground (extrinsic) calibration of a camera source in JupyterLab.

    Parameters
    ----------
    source : str or live source (``"ros:ROBOT"``, a recording, ...)
    intrinsics : CameraModel, path of a ``camera_intrinsic`` YAML, or a
        :class:`~dtscal_lib.ui.intrinsic.LiveCalibrator` (its calibration is used as soon as
        there is one)
    board, robot, calibration_dir, realtime, loop, autostart : as for the calibrator; a
        recording loops by default (the robot stands still on the board)
    """

    def __init__(self, source, intrinsics, *, board: Board = DUCKIETOWN_BOARD, robot: str | None = None,
                 calibration_dir="calibrations", realtime: bool = True, loop: bool = True,
                 autostart: bool = True):
        import ipywidgets as w

        self.board = board
        self.spec = str(getattr(source, "spec", source))
        self.source = open_live(source, realtime=realtime, loop=loop) if isinstance(source, (str, Path)) else source
        if isinstance(intrinsics, (str, Path)):
            intrinsics = calib_files.load_intrinsics(intrinsics).camera()
        self._intrinsics = intrinsics
        #: where the fits happen (the session the command line drives), keeping the best
        self.session = ExtrinsicSession(None, board, keep="best", source=self.spec,
                                        robot=robot_name(self.spec, self.source, robot) or "camera")
        self.ground_true = ground_points(board)
        self.current = None
        self.reason = ""
        self.bad: Counter = Counter()
        self.frames_seen = 0
        self.state = "connecting"
        self._lock = threading.RLock()
        self._maps_for = None
        self._maps = None

        lay = w.Layout
        self.status = w.HTML(render.message_html(f"connecting to {self.spec} ..."))
        self.image = w.Image(format="jpeg", layout=lay(width="480px"))
        self.top = w.Image(format="jpeg", layout=lay(width="320px"))
        self.error_text = w.HTML("fit error: -")
        self.grid = w.Image(format="jpeg", layout=lay(width="480px"))
        self.birdseye = w.Image(format="jpeg", layout=lay(width="320px"))
        self.save_button = w.Button(description="SAVE", disabled=True, button_style="success",
                                    tooltip="write the best homography so far")
        self.reset_button = w.Button(description="RESET BEST")
        self.reconnect_button = w.Button(description="RECONNECT", icon="refresh")
        self.robot_text = w.Text(value=self.robot, description="robot")
        self.folder_text = w.Text(value=str(calibration_dir), description="folder", layout=lay(width="420px"))
        self.format = w.Dropdown(options=[("classic (homography: 9 values)", "classic"),
                                          ('version "2" (resolution-independent)', "2")],
                                 value="classic", description="format")
        self.target = w.Dropdown(options=[("calibration folder", "folder"), ("folder and robot (upload)", "robot")],
                                 value="robot" if self.spec.startswith("ros:") else "folder", description="save to")
        self.keep_anyway = w.Checkbox(value=False, description="keep anyway (expert)", indent=False)
        self.message = w.HTML("")
        for b, fn in ((self.save_button, self.save), (self.reset_button, self.reset_best),
                      (self.reconnect_button, self.reconnect)):
            b.on_click(lambda _b, fn=fn: fn())
        self.robot_text.observe(lambda ch: setattr(self, "robot", ch["new"].strip()), "value")
        self.widget = w.VBox([
            self.status,
            w.HBox([self.image, w.VBox([w.HTML("<b>top view of the board</b>"), self.top, self.error_text])]),
            w.HBox([self.save_button, self.reset_button, self.reconnect_button, self.robot_text]),
            w.HBox([self.folder_text, self.format, self.target, self.keep_anyway]), self.message,
            w.HTML("<b>validation</b> with the best homography: ground grid (5 cm) on the live image, "
                   "and a bird's-eye view"),
            w.HBox([self.grid, self.birdseye]),
        ])
        # the views go out no faster than the page displays them (the newest waits, older are dropped)
        self._pacer = DisplayPacer(self._display)
        self.widget.children = (*self.widget.children, ack_widgets(self._pacer))
        self.widget.add_class("dtscal-tool")
        self._waiting_shown = 0.0
        self._closed = threading.Event()
        self.loop = FrameLoop(self.source, self._on_frame, self._on_status)
        if autostart:
            self.start()

    def start(self) -> None:
        """Start the frame loop, or, while there is no intrinsic calibration, once there is one:
        until then the tool waits without receiving or processing frames (an idle tool costs no CPU)."""
        if self.camera() is not None:
            self.loop.start()
            return
        self.status.value = render.message_html(
            f"{self.spec}: waiting for an intrinsic calibration (CALIBRATE in the calibrator above)")
        self.error_text.value = render.message_html(
            "waiting for an intrinsic calibration: CALIBRATE in the calibrator above", "error")

        def wait():
            while not self._closed.wait(0.2):
                if self.camera() is not None:
                    self.loop.start()
                    return

        threading.Thread(target=wait, daemon=True, name="dtscal-extrinsic-wait").start()

    def _repr_mimebundle_(self, **kw):
        bundle = self.widget._repr_mimebundle_(**kw)
        # the widget's own text form changes with every frame; this one is stable (stored outputs)
        bundle["text/plain"] = "live extrinsic tool (shown as a widget in JupyterLab)"
        return bundle

    # ------------------------------------------------------------------ the session's state
    @property
    def robot(self) -> str:
        return self.session.robot

    @robot.setter
    def robot(self, name: str) -> None:
        self.session.robot = name

    @property
    def best(self):
        """The best fit so far (:class:`~dtscal_lib.ground.ExtrinsicResult`), or None."""
        return self.session.best

    @property
    def best_frame(self) -> int:
        return self.session.best_frame

    # ------------------------------------------------------------------ intrinsics
    def camera(self) -> CameraModel | None:
        """The intrinsic calibration in use (None while a live calibrator has none yet)."""
        src = self._intrinsics
        if isinstance(src, CameraModel) or src is None:
            return src
        return src.camera()

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

    # ------------------------------------------------------------------ frame loop
    def _on_status(self, st) -> None:
        self.state = st.state
        self.status.value = render.source_status_html(self.spec, st, dict(st.bad), "The best fit is kept")

    #: while there is no intrinsic calibration the tool idles: one camera frame per this many seconds
    WAITING_PERIOD = 1.0

    def _on_frame(self, frame) -> bool | None:
        arrival = getattr(frame, "arrival", None) or time.time()  # frames made by hand have none
        img = frame.image
        if img is None or img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
            self.bad["odd_frame"] += 1
            return False
        self.frames_seen += 1
        cam = self.camera()
        if cam is None:  # idle: show the camera now and then, and let the loop rest (no CPU burnt)
            now = time.monotonic()
            if now - self._waiting_shown < self.WAITING_PERIOD:
                self.loop.idle(self.WAITING_PERIOD / 4)
                return False
            self._waiting_shown = now
            self.error_text.value = render.message_html(
                "waiting for an intrinsic calibration: CALIBRATE in the calibrator above", "error")
            token = self._pacer.next_token()
            self._pacer.offer(token, (img, None, None, -1, None, frame.index, arrival, token))
            self.loop.idle(self.WAITING_PERIOD / 4)
            return
        if (img.shape[1], img.shape[0]) != cam.size:
            self.bad["size_mismatch"] += 1
            return False
        rect, cam = self._rectify(img, cam)
        offer = self.session.offer(frame, camera=cam)
        res = offer.detection
        if res is None and offer.reason == Reason.DETECTOR_ERROR:
            self.reason = "OpenCV could not process this frame"
            self.bad["detector_error"] += 1
        elif res is None:
            self.reason = str(self.session.last_error)
        if res is not None:
            with self._lock:
                self.current = res
                best = self.best
            if self.save_button.disabled:
                self.save_button.disabled = False
        else:
            with self._lock:
                self.current = None
                best = self.best
        token = self._pacer.next_token()
        reason = "" if res is not None else self.reason
        self._pacer.offer(token, (rect, res, best, self.best_frame, reason, frame.index, arrival, token))

    def _display(self, payload) -> None:
        """Put one processed frame into the views (called by the display pacer): the camera view
        with its arrival stamp, the fit error, the top view and the validation views. Drawing
        happens here, so a frame the page has no time for costs nothing more."""
        image, res, best, best_frame, reason, index, arrival, token = payload
        if res is best is reason is None:  # waiting for the intrinsics: the camera view only
            self._show_image(image, index, arrival, token)
            return
        view = image.copy()
        fit = None
        if res is not None:
            for p in res.corners_rectified:
                cv2.circle(view, (int(round(p[0])), int(round(p[1]))), 3, (0, 0, 255), -1, cv2.LINE_AA)
            fit = pixel_to_ground(res.H, res.corners_rectified)
            err, best_err = float(np.mean(res.residual_mm)), float(np.mean(best.residual_mm))
            self.error_text.value = (
                f'<div class="dtscal-fit" data-now="{err:.4f}" data-best="{best_err:.4f}">'
                f"fit error now: <b>{err:.2f} mm</b> (max {np.max(res.residual_mm):.2f} mm)<br>"
                f"best so far: <b>{best_err:.2f} mm</b> (frame {best_frame})</div>")
        else:
            self.error_text.value = render.message_html(f"no fit on this frame: {reason}", "error")
        self._show_image(view, index, arrival, token)
        self.top.value = render.encode_jpeg(render.top_view(self.ground_true, fit))
        if best is not None:
            self.grid.value = render.encode_jpeg(draw_ground_grid(image, best.H))
            self.birdseye.value = render.encode_jpeg(birdseye_view(image, best.H, px_per_m=600))

    def _show_image(self, view, index, arrival, token) -> None:
        with self.image.hold_sync():
            self.image.value = render.encode_jpeg(view)
            self.image._dom_classes = render.stamp_classes(index, arrival, token, "extrinsic")

    # ------------------------------------------------------------------ actions
    def save(self) -> str:
        """Write the best homography so far as ``camera_extrinsic/<ROBOT>.yaml`` in the folder
        (classic or version-2 format) and, with the target "robot", upload it to the robot.

        The session's gate comes first, as for ``dtscal calibrate-extrinsics``: a homography the kit does
        not believe is refused (nothing written); "keep anyway" writes it as ``<ROBOT>.rejected.yaml``
        beside the robot's file and never uploads it."""
        with self._lock:
            best, frame = self.best, self.best_frame
        if best is None:
            return self._say("nothing to save yet: no frame gave a fit", "error")
        try:
            path = self.session.write(self.folder_text.value.strip(), keep_anyway=bool(self.keep_anyway.value),
                                      fmt=self.format.value)
            text = (f"SAVE: wrote {path} (best fit, frame {frame}, mean error "
                    f"{np.mean(best.residual_mm):.2f} mm)")
            if self.session.doubts:
                return self._say(text + "; kept against the kit's doubts: " + "; ".join(map(str, self.session.doubts))
                                 + ". It is not sent to the robot.", "error")
            if self.target.value == "robot":
                text += "; " + self.session.commit(master_uri=getattr(self.source, "master", None),
                                                   fmt=self.format.value)
        except ImplausibleCalibrationError as exc:
            doubts = "".join(f"<br>- {d}" for d in exc.doubts)
            return self._say(f"SAVE refused: the kit does not believe this homography, nothing was written:{doubts}"
                             "<br>Place the robot on the board as in the Duckietown procedure, or, as an expert, "
                             f"tick \"keep anyway\" to keep it as {self.robot}{calib_files.REJECTED_SUFFIX}.yaml "
                             "beside the robot's file.", "error")
        except (DtscalError, OSError) as exc:
            return self._say(f"SAVE failed: {exc}. The previous file is unchanged.", "error")
        return self._say(text, "ok")

    def reset_best(self) -> None:
        """Forget the best fit (e.g. after moving the robot on the board)."""
        self.session.forget()
        self.save_button.disabled = True

    def _say(self, text: str, kind: str = "info") -> str:
        self.message.value = render.message_html(text, kind)
        return text

    def reconnect(self) -> str:
        try:
            self.loop.reconnect()
        except DtscalError as exc:
            return self._say(f"RECONNECT failed: {exc}", "error")
        return self._say(f"reconnecting to {self.spec}")

    def close(self) -> None:
        self._closed.set()
        self.loop.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
