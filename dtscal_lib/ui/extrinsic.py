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
What happens to a frame and what SAVE does, without widgets, is
:class:`~dtscal_lib.ui.extrinsic_driver.ExtrinsicDriver`; :class:`LiveExtrinsics` adds the widgets only.

Examples
--------
>>> tool = LiveExtrinsics("data/session/extrinsics.bag", intrinsics=calibrator)   # doctest: +SKIP
"""

from __future__ import annotations

import cv2
import numpy as np

from ..boards import DUCKIETOWN_BOARD, Board
from ..figure import ARROW_COLOR, bgr
from ..ground import birdseye_view, draw_ground_grid, pixel_to_ground
from . import render
from .extrinsic_driver import KEPT, ExtrinsicDriver, _MapsCamera  # noqa: F401  (_MapsCamera's home was here)
from .frameloop import DisplayPacer, ack_widgets


class LiveExtrinsics(ExtrinsicDriver):
    """Live ground (extrinsic) calibration of a camera source in JupyterLab.

    Parameters
    ----------
    source : str or live source (``"ros:ROBOT"``, a recording, ...)
    intrinsics : CameraModel, path of a ``camera_intrinsic`` YAML, or a
        :class:`~dtscal_lib.ui.intrinsic.LiveCalibrator` (its calibration is used as soon as
        there is one)
    board, robot, calibration_dir, realtime, loop, autostart : as for the calibrator; a
        recording loops by default (the robot stands still on the board)
    robot_type : ``"duckiebot"`` or ``"dd24"``, when the board does not say which robot it is
        (:mod:`dtscal_lib.profiles`; ``--robot-type`` of the command line)
    """

    def __init__(self, source, intrinsics, *, board: Board = DUCKIETOWN_BOARD, robot: str | None = None,
                 calibration_dir="calibrations", realtime: bool = True, loop: bool = True,
                 autostart: bool = True, robot_type: str | None = None):
        import ipywidgets as w

        super().__init__(source, intrinsics, board=board, robot=robot, realtime=realtime, loop=loop,
                         robot_type=robot_type)
        lay = w.Layout
        self.status = w.HTML(render.message_html(f"connecting to {self.spec} ..."))
        wait = render.placeholder_jpeg
        self.image = w.Image(value=wait(f"waiting for the first frame from {self.spec}"), format="jpeg",
                             layout=lay(width="480px"))
        self.top = w.Image(value=wait("the board seen from above appears with the first fit", (320, 416)),
                           format="jpeg", layout=lay(width="320px"))
        self.error_text = w.HTML("fit error: -")
        self.grid = w.Image(value=wait("the ground grid appears with the first fit"), format="jpeg",
                            layout=lay(width="480px"))
        self.birdseye = w.Image(value=wait("the bird's-eye view appears with the first fit", (320, 416)),
                                format="jpeg", layout=lay(width="320px"))
        self.save_button = w.Button(description="SAVE", disabled=True, button_style="success",
                                    tooltip="write the best homography so far")
        self.reset_button = w.Button(description="RESET BEST")
        self.reconnect_button = w.Button(description="RECONNECT", icon="refresh")
        self.robot_text = w.Text(value=self.robot, description="robot")
        self.folder_text = w.Text(value=str(calibration_dir), description="folder", layout=lay(width="420px"))
        self.format = w.Dropdown(options=[("classic (homography: 9 values)", "classic"),
                                          ('version "2" (resolution-independent)', "2")],
                                 value="classic", description="format")
        self.target = w.Dropdown(options=[("calibration folder", "folder"), ("folder and robot over DTPS", "dtps"),
                                          ("folder and robot (file upload)", "robot")],
                                 value="dtps" if self.spec.startswith("dtps:") else "robot"
                                 if self.spec.startswith("ros:") else "folder", description="save to")
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
        if autostart:
            self.start()

    def start(self) -> None:
        """Start the frame loop, or, while there is no intrinsic calibration, once there is one:
        until then the tool waits without receiving or processing frames (an idle tool costs no CPU)."""
        super().start(on_wait=self._show_waiting)

    def _show_waiting(self) -> None:
        self.status.value = render.message_html(
            f"{self.spec}: waiting for an intrinsic calibration (CALIBRATE in the calibrator above)")
        self.error_text.value = render.message_html(
            "waiting for an intrinsic calibration: CALIBRATE in the calibrator above", "error")

    def _repr_mimebundle_(self, **kw):
        bundle = self.widget._repr_mimebundle_(**kw)
        # the widget's own text form changes with every frame; this one is stable (stored outputs)
        bundle["text/plain"] = "live extrinsic tool (shown as a widget in JupyterLab)"
        return bundle

    # ------------------------------------------------------------------ frame loop
    def _on_status(self, st) -> None:
        super()._on_status(st)
        self.status.value = render.source_status_html(self.spec, st, dict(st.bad), KEPT)
        if st.frames == 0 and st.state in ("error", "ended"):  # nothing to show: say so where the image would be
            self.image.value = render.placeholder_jpeg(f"no frame: could not connect to {self.spec} "
                                                       "(the status line says why)", (640, 480))

    def _on_frame(self, frame) -> bool | None:
        """The loop body: the driver fits the frame; the views get it through the display pacer."""
        got = self.take(frame)
        if got is None:
            return False
        if got.reason is None:  # waiting for the intrinsics: the camera now and then, the loop rests
            self.error_text.value = render.message_html(
                "waiting for an intrinsic calibration: CALIBRATE in the calibrator above", "error")
        elif got.fit is not None and self.save_button.disabled:
            self.save_button.disabled = False
        token = self._pacer.next_token()
        self._pacer.offer(token, (got.image, got.fit, got.best, got.best_frame, got.reason, frame.index,
                                  got.arrival, token))
        if got.reason is None:
            self.loop.idle(self.WAITING_PERIOD / 4)

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
                cv2.circle(view, (int(round(p[0])), int(round(p[1]))), 3, bgr(ARROW_COLOR), -1, cv2.LINE_AA)
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

    # ------------------------------------------------------------------ the buttons
    def _say(self, text: str, kind: str = "info") -> str:
        self.message.value = render.message_html(text, kind)
        return text

    def save(self) -> str:
        """Write the best homography so far as ``camera_extrinsic/<ROBOT>.yaml`` in the folder
        (classic or version-2 format) and, with the target "robot", upload it to the robot.

        The session's gate comes first, as for ``dtscal calibrate-extrinsics``: a homography the kit does
        not believe is refused (nothing written); "keep anyway" writes it as ``<ROBOT>.rejected.yaml``
        beside the robot's file and never uploads it."""
        return self._say(*self.save_to(self.folder_text.value.strip(), keep_anyway=bool(self.keep_anyway.value),
                                       fmt=self.format.value, target=self.target.value))

    def reset_best(self) -> None:
        """Forget the best fit (e.g. after moving the robot on the board)."""
        super().reset_best()
        self.save_button.disabled = True

    def reconnect(self) -> str:
        return self._say(*self.reconnect_to())
