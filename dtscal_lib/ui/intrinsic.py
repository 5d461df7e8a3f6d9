"""The live intrinsic calibrator: ROS's ``cameracalibrator.py`` as an ipywidgets application.

Every frame of the source is searched for the board with the fast detector
(:func:`dtscal_lib.detect.detect_board`), drawn, sent to the browser as one JPEG and offered
to ROS's coverage rule (:class:`dtscal_lib.coverage.CoverageTracker`). The four X / Y / Size /
Skew bars turn green when full; CALIBRATE is enabled by ROS's rule (all bars full, or 40
samples) and runs in its own thread, so the image and the bars keep moving while it works
(ROS's window freezes: image_pipeline issue 762). The results panel shows K, the distortion,
the RMS error, a per-sample error chart and the standard deviations; an undistorted preview
with an alpha slider follows. COMMIT sends the calibration to the robot over ROS
(``set_camera_info``) or writes ``camera_intrinsic/<ROBOT>.yaml`` into a calibration folder;
SAVE writes the samples and the YAML into one zip that :meth:`LiveCalibrator.load` reads back.

The calibration itself happens in a :class:`dtscal_lib.session.IntrinsicSession`, the same one
``dtscal calibrate-intrinsics`` drives: COMMIT goes through its gate, so the live tool refuses what
the command line refuses (nothing written; "keep anyway" writes ``ROBOT.rejected.yaml`` beside, and
never sends it to the robot). What happens to a frame and what each button does, without widgets, is
:class:`~dtscal_lib.ui.intrinsic_driver.IntrinsicDriver`; :class:`LiveCalibrator` adds the widgets
only. Every button has a method of the same name, so the tool can be driven from Python (tests,
scripts) as well as by clicks.

Examples
--------
>>> app = LiveCalibrator("data/session/intrinsics.bag")     # doctest: +SKIP
>>> app                                                       # doctest: +SKIP
"""

from __future__ import annotations

from .. import duckietown as dt
from ..boards import DUCKIETOWN_BOARD, Board
from ..camera import DIST_MODELS
from ..coverage import CoverageTracker
from ..detect import draw_detection
from ..session import robot_name
from . import render
from .frameloop import DisplayPacer, ack_widgets
from .intrinsic_driver import KEPT, IntrinsicDriver
from .render import rectification_maps_fast, verdict_html  # noqa: F401  (their home was here)


def robot_of(spec: str, source=None) -> str | None:
    """The robot a source belongs to (:func:`dtscal_lib.session.robot_name`, the kit's one rule)."""
    return robot_name(spec, source)


class LiveCalibrator(IntrinsicDriver):
    """Live intrinsic calibration of a camera source in JupyterLab.

    Parameters
    ----------
    source : str or live source
        ``"ros:ROBOT"`` (a Duckiebot over ROS), ``"device:0"``, a stream URL, or a recording
        (a ROS 1 bag), or an already opened live source.
    board : the calibration board (default Duckietown's 7x5 inner corners, 31 mm)
    robot : robot name for the files (default: from the source)
    calibration_dir : folder that receives ``camera_intrinsic/<ROBOT>.yaml`` on an offline COMMIT
    model : ``"plumb_bob"`` (ROS default), ``"radial2"``, ``"rational_polynomial"`` or ``"equidistant"`` (ROS's
        other two, calibrated by OpenCV)
    realtime, loop : recordings: play at the recorded rate (or as fast as possible); replay at the end
    autostart : start the frame loop at once
    """

    def __init__(self, source, *, board: Board = DUCKIETOWN_BOARD, robot: str | None = None,
                 calibration_dir="calibrations", model: str = "plumb_bob", realtime: bool = True,
                 loop: bool = False, autostart: bool = True):
        import ipywidgets as w

        super().__init__(source, board=board, robot=robot, model=model, realtime=realtime, loop=loop)
        lay = w.Layout
        self.status = w.HTML(render.message_html(f"connecting to {self.spec} ..."))
        self.image = w.Image(value=render.placeholder_jpeg(f"waiting for the first frame from {self.spec}"),
                             format="jpeg", layout=lay(width="640px"))
        self.bars = w.HTML(render.bars_html(CoverageTracker(board).bars()))
        self.count = w.HTML("samples: 0")
        self.thumb_box = w.HBox([], layout=lay(overflow="auto", width="660px", min_height="96px"))
        self.calibrate_button = w.Button(description="CALIBRATE", disabled=True, button_style="primary",
                                         tooltip="enabled when every bar is green or at 40 samples")
        self.commit_button = w.Button(description="COMMIT", disabled=True, button_style="success")
        self.keep_anyway = w.Checkbox(value=False, description="keep anyway (expert)", indent=False,
                                      tooltip="COMMIT a calibration the kit refuses as ROBOT.rejected.yaml beside "
                                              "the robot's file (never sent to the robot)")
        self.save_button = w.Button(description="SAVE", disabled=False)
        self.reconnect_button = w.Button(description="RECONNECT", icon="refresh")
        robot_link = "dtps" if self.spec.startswith("dtps:") else "ros" if self.spec.startswith("ros:") else "folder"
        self.commit_target = w.Dropdown(options=[("robot over DTPS (its key-value store)", "dtps"),
                                                 (f"robot over ROS ({dt.SET_CAMERA_INFO})", "ros"),
                                                 ("calibration folder", "folder")],
                                        value=robot_link, description="commit to")
        self.robot_text = w.Text(value=self.robot, description="robot")
        # the lens model of the next CALIBRATE (ROS's calibrator: plumb_bob, rational_polynomial, equidistant)
        self.model_choice = w.Dropdown(options=list(DIST_MODELS), value=model, description="lens model")
        self.model_choice.observe(lambda ch: self.set_model(ch["new"]), "value")
        self.folder_text = w.Text(value=str(calibration_dir), description="folder",
                                  layout=lay(width="420px"))
        self.archive_text = w.Text(value=f"{self.robot}_session.zip", description="archive",
                                   layout=lay(width="420px"))
        self.message = w.HTML("")
        self.results = w.HTML(render.message_html("no calibration yet: fill the bars, then CALIBRATE"))
        self.preview = w.Image(value=render.placeholder_jpeg("the undistorted view appears here after CALIBRATE"),
                               format="jpeg", layout=lay(width="640px"))
        self.alpha = w.FloatSlider(value=0.0, min=0.0, max=1.0, step=0.05, description="alpha",
                                   continuous_update=False)
        for b, fn in ((self.calibrate_button, self.calibrate), (self.commit_button, self.commit),
                      (self.save_button, self.save), (self.reconnect_button, self.reconnect)):
            b.on_click(lambda _b, fn=fn: fn())
        self.robot_text.observe(lambda ch: setattr(self, "robot", ch["new"].strip()), "value")
        self.widget = w.VBox([
            self.status, self.image,
            w.HBox([w.VBox([self.bars, self.count], layout=lay(width="330px")),
                    w.VBox([w.HBox([self.calibrate_button, self.commit_button, self.save_button,
                                    self.reconnect_button]), self.commit_target, self.robot_text,
                                    self.model_choice, self.keep_anyway])]),
            w.HTML("<b>samples kept</b> (click a sample's button to drop it)"), self.thumb_box,
            self.folder_text, self.archive_text, self.message,
            w.HTML("<b>results</b>"), self.results,
            w.HTML("<b>undistorted live preview</b> (after CALIBRATE; alpha 0 crops to valid pixels, 1 keeps all)"),
            self.alpha, self.preview,
        ])
        # live images go out no faster than the page displays them (the newest waits, older are dropped)
        self._pacer = DisplayPacer(self._display)
        self.widget.children = (*self.widget.children, ack_widgets(self._pacer))
        self.widget.add_class("dtscal-tool")
        if autostart:
            self.loop.start()

    def _repr_mimebundle_(self, **kw):
        bundle = self.widget._repr_mimebundle_(**kw)
        # the widget's own text form changes with every frame; this one is stable (stored outputs)
        bundle["text/plain"] = "live calibrator (shown as a widget in JupyterLab)"
        return bundle

    # ------------------------------------------------------------------ frame loop
    def _on_status(self, st) -> None:
        super()._on_status(st)
        self.status.value = render.source_status_html(self.spec, st, {**st.bad, **self.bad}, KEPT)
        if st.frames == 0 and st.state in ("error", "ended"):  # nothing to show: say so where the image would be
            self.image.value = render.placeholder_jpeg(f"no frame: could not connect to {self.spec} "
                                                       "(the status line says why)")

    def _on_frame(self, frame) -> bool | None:
        """The loop body: the driver takes the frame (detect, offer); draw, publish (False: frame skipped)."""
        got = self.take(frame)
        if got is None:
            self.count.value = self.skipped_text()
            return False
        token = self._pacer.next_token()
        self._pacer.offer(token, (draw_detection(got.image, got.detection), got.image, frame.index, got.arrival,
                                  token))
        if got.added:
            self.bars.value = render.bars_html(got.bars)
            self.count.value = f"samples: {got.n}"
            self._add_thumb(got.n - 1)
        if self.calibrate_button.disabled == got.ready:
            self.calibrate_button.disabled = not got.ready

    def _display(self, payload) -> None:
        """Put one processed frame into the widgets (called by the display pacer): the image with
        its arrival stamp, and the undistorted preview once there is a calibration."""
        drawn, img, index, arrival, token = payload
        jpeg = render.encode_jpeg(drawn)
        with self.image.hold_sync():
            self.image.value = jpeg
            self.image._dom_classes = render.stamp_classes(index, arrival, token, "intrinsic")
        out = self._preview.undistort(img, self.result, float(self.alpha.value), lambda: self.result)
        if out is not None:
            self.preview.value = render.encode_jpeg(out)

    def _add_thumb(self, i: int) -> None:
        import ipywidgets as w

        im = w.Image(value=self.thumbs[i], format="jpeg", layout=w.Layout(width="96px"))
        b = w.Button(description=f"drop {i + 1}", layout=w.Layout(width="96px"), tooltip="drop this sample")
        box = w.VBox([im, b], layout=w.Layout(min_width="100px", flex="0 0 auto"))
        b.on_click(lambda _b, box=box: self.drop_sample(list(self.thumb_box.children).index(box)))
        self.thumb_box.children = (*self.thumb_box.children, box)

    def _show_samples(self, bars, n: int) -> None:
        """The bars, the count and every thumbnail anew (a sample dropped, an archive loaded)."""
        self.bars.value = render.bars_html(bars)
        self.count.value = f"samples: {n}"
        old, self.thumb_box.children = self.thumb_box.children, ()
        for box in old:  # close the widgets too, or the kernel keeps their models
            for child in box.children:
                child.close()
            box.close()
        for i in range(len(self.thumbs)):
            self._add_thumb(i)
        self.calibrate_button.disabled = not self.background.can_start()

    # ------------------------------------------------------------------ CALIBRATE's news (from its thread)
    def _calibrated(self, result) -> None:
        super()._calibrated(result)
        # the preview's maps are made here, in the calibration's thread: the frame loop never builds them
        self._preview.build(result, float(self.alpha.value), lambda: self.result)
        self.results.value = render.calibration_html(result, self.dropped, self._calibrating_from)
        self.commit_button.disabled = False

    def _failed(self, message: str) -> None:
        keep = " The previous calibration is kept." if self.result is not None else ""
        self.results.value = render.message_html(message + keep, "error")

    def _verdict(self, result, quality) -> None:
        """The verdict follows the result (it can take longer than the calibration)."""
        super()._verdict(result, quality)
        verdict = verdict_html(quality)
        if verdict:
            against = self.compare_with_robot(self.folder_text.value.strip() or ".")
            self.results.value = render.calibration_html(result, self.dropped, self._calibrating_from, verdict,
                                                         against)

    def _calibrate_ended(self) -> None:
        self.calibrate_button.disabled = not self.background.can_start()

    # ------------------------------------------------------------------ the buttons
    def _say(self, text: str, kind: str = "info") -> str:
        self.message.value = render.message_html(text, kind)
        return text

    def drop_sample(self, i: int) -> None:
        """Forget sample ``i`` (0-based): its thumbnail goes, the bars are recomputed."""
        shown = self.drop(i)
        if shown is not None:
            self._show_samples(*shown)

    def calibrate(self, wait: bool = False):
        """Calibrate from the samples in a background thread; ``wait=True`` blocks until done.

        Returns the ``CalibrationResult`` (``wait=True``) or the thread. A failure (too few or
        degenerate samples) is shown in the results panel; the previous calibration stays.
        """
        def started(n: int) -> None:
            self.calibrate_button.disabled = True
            self.results.value = render.message_html(f"calibrating from {n} samples ...")

        job = self.start_calibration(started)
        if wait:
            job.join()
            return self.result
        return job

    def commit(self) -> str:
        """Write ``camera_intrinsic/<ROBOT>.yaml`` into the calibration folder and, with the
        target "robot over DTPS", store it on the robot through its key-value store; with "robot over ROS",
        send it to ``/<ROBOT>/camera_node/set_camera_info``.

        The session's gate comes first, as for ``dtscal calibrate-intrinsics``: a calibration the kit
        does not believe is refused (nothing written, nothing sent); with "keep anyway" it is written as
        ``<ROBOT>.rejected.yaml`` beside the robot's file and never sent. On failure the message says
        why; the previous file on the robot or in the folder is unchanged, and SAVE still keeps the new
        calibration.
        """
        return self._say(*self.commit_to(self.folder_text.value.strip(), keep_anyway=bool(self.keep_anyway.value),
                                         target=self.commit_target.value))

    def save(self, path=None) -> str:
        """Write the samples (and the calibration, if any) into one zip archive."""
        return self._say(*self.save_to(path or self.archive_text.value.strip()))

    def load(self, path) -> str:
        """Replace the samples by those of a SAVE archive (CALIBRATE again to recalibrate)."""
        text, kind, shown = self.load_from(path)
        if shown is not None:
            self._show_samples(*shown)
        return self._say(text, kind)

    def reconnect(self) -> str:
        """Re-open the source; samples and calibration are kept."""
        return self._say(*self.reconnect_to())
