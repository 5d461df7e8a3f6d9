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
never sends it to the robot). :class:`LiveCalibrator` holds the widgets and the threads; every
button has a method of the same name, so the tool can be driven from Python (tests, scripts) as
well as by clicks.

Examples
--------
>>> app = LiveCalibrator("data/session/intrinsics.bag")     # doctest: +SKIP
>>> app                                                       # doctest: +SKIP
"""

from __future__ import annotations

import time
from collections import Counter
from pathlib import Path

import numpy as np

from .. import calib_files
from ..boards import DUCKIETOWN_BOARD, Board
from ..camera import CameraModel
from ..coverage import CoverageTracker
from ..detect import draw_detection
from ..errors import DtscalError, ImplausibleCalibrationError, Reason
from ..session import MIN_SAMPLES, IntrinsicSession, robot_name
from ..sources.live import open_live
from . import render
from .archive import load_session, save_session
from .frameloop import DisplayPacer, FrameLoop, ack_widgets
from .render import rectification_maps_fast, verdict_html  # noqa: F401  (their home was here)
from .background import BackgroundCalibration, PreviewMaps


def robot_of(spec: str, source=None) -> str | None:
    """The robot a source belongs to (:func:`dtscal_lib.session.robot_name`, the kit's one rule)."""
    return robot_name(spec, source)


class LiveCalibrator:
    """Live intrinsic calibration of a camera source in JupyterLab.

    Parameters
    ----------
    source : str or live source
        ``"ros:ROBOT"`` (a Duckiebot over ROS), ``"device:0"``, a stream URL, or a recording
        (a ROS 1 bag), or an already opened live source.
    board : the calibration board (default Duckietown's 7x5 inner corners, 31 mm)
    robot : robot name for the files (default: from the source)
    calibration_dir : folder that receives ``camera_intrinsic/<ROBOT>.yaml`` on an offline COMMIT
    model : ``"plumb_bob"`` (ROS default) or ``"radial2"``
    realtime, loop : recordings: play at the recorded rate (or as fast as possible); replay at the end
    autostart : start the frame loop at once
    """

    def __init__(self, source, *, board: Board = DUCKIETOWN_BOARD, robot: str | None = None,
                 calibration_dir="calibrations", model: str = "plumb_bob", realtime: bool = True,
                 loop: bool = False, autostart: bool = True):
        import ipywidgets as w

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

        # ---- widgets
        lay = w.Layout
        self.status = w.HTML(render.message_html(f"connecting to {self.spec} ..."))
        self.image = w.Image(format="jpeg", layout=lay(width="640px"))
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
        ros = self.spec.startswith("ros:")
        self.commit_target = w.Dropdown(options=[("robot over ROS (set_camera_info)", "ros"),
                                                 ("calibration folder", "folder")],
                                        value="ros" if ros else "folder", description="commit to")
        self.robot_text = w.Text(value=self.robot, description="robot")
        self.folder_text = w.Text(value=str(calibration_dir), description="folder",
                                  layout=lay(width="420px"))
        self.archive_text = w.Text(value=f"{self.robot}_session.zip", description="archive",
                                   layout=lay(width="420px"))
        self.message = w.HTML("")
        self.results = w.HTML(render.message_html("no calibration yet: fill the bars, then CALIBRATE"))
        self.preview = w.Image(format="jpeg", layout=lay(width="640px"))
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
                                    self.keep_anyway])]),
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
        self.loop = FrameLoop(self.source, self._on_frame, self._on_status)
        if autostart:
            self.loop.start()

    # ------------------------------------------------------------------ display
    def _repr_mimebundle_(self, **kw):
        bundle = self.widget._repr_mimebundle_(**kw)
        # the widget's own text form changes with every frame; this one is stable (stored outputs)
        bundle["text/plain"] = "live calibrator (shown as a widget in JupyterLab)"
        return bundle

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

    # ------------------------------------------------------------------ frame loop
    def _on_status(self, st) -> None:
        self.state = st.state
        self.status.value = render.source_status_html(self.spec, st, {**st.bad, **self.bad}, "Every sample is kept")

    def _on_frame(self, frame) -> bool | None:
        """The loop body: detect, offer to coverage, draw, encode, publish (False: frame skipped)."""
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
        drawn = draw_detection(img, det)
        token = self._pacer.next_token()
        self._pacer.offer(token, (drawn, img, frame.index, arrival, token))
        if added:
            self.bars.value = render.bars_html(bars)
            self.count.value = f"samples: {n}"
            self._add_thumb(n - 1)
        enable = ready and not self.background.busy and n >= MIN_SAMPLES
        if self.calibrate_button.disabled == enable:
            self.calibrate_button.disabled = not enable

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

    def _skip(self, reason: str) -> bool:
        """Count a frame the calibrator cannot use (the count shows under the bars); returns False."""
        self.bad[reason] += 1
        n = len(self.tracker.samples) if self.tracker else 0
        self.count.value = f"samples: {n}; frames skipped: " + ", ".join(
            f"{k} {v}" for k, v in sorted(self.bad.items()))
        return False

    def _add_thumb(self, i: int) -> None:
        import ipywidgets as w

        im = w.Image(value=self.thumbs[i], format="jpeg", layout=w.Layout(width="96px"))
        b = w.Button(description=f"drop {i + 1}", layout=w.Layout(width="96px"), tooltip="drop this sample")
        box = w.VBox([im, b], layout=w.Layout(min_width="100px", flex="0 0 auto"))
        b.on_click(lambda _b, box=box: self.drop_sample(list(self.thumb_box.children).index(box)))
        self.thumb_box.children = (*self.thumb_box.children, box)

    def _rebuild_thumbs(self) -> None:
        old, self.thumb_box.children = self.thumb_box.children, ()
        for box in old:  # close the widgets too, or the kernel keeps their models
            for child in box.children:
                child.close()
            box.close()
        for i in range(len(self.thumbs)):
            self._add_thumb(i)

    # ------------------------------------------------------------------ actions
    @property
    def samples(self):
        return [] if self.tracker is None else list(self.tracker.samples)

    def drop_sample(self, i: int) -> None:
        """Forget sample ``i`` (0-based): its thumbnail goes, the bars are recomputed."""
        with self._lock:
            if self.tracker is None or not 0 <= i < len(self.tracker.samples):
                return
            del self.tracker.samples[i]
            del self.thumbs[i]
            bars, n = self.tracker.bars(), len(self.tracker.samples)
        self.bars.value = render.bars_html(bars)
        self.count.value = f"samples: {n}"
        self._rebuild_thumbs()
        self.calibrate_button.disabled = not self.background.can_start()

    def calibrate(self, wait: bool = False):
        """Calibrate from the samples in a background thread; ``wait=True`` blocks until done.

        Returns the ``CalibrationResult`` (``wait=True``) or the thread. A failure (too few or
        degenerate samples) is shown in the results panel; the previous calibration stays.
        """
        with self._lock:
            if not self.background.busy:
                self.calibrate_button.disabled = True
                self._calibrating_from = len(self.samples)
                self.results.value = render.message_html(f"calibrating from {self._calibrating_from} samples ...")
            job = self.background.start(self.prepare_calibration)
        if wait:
            job.join()
            return self.result
        return job

    def prepare_calibration(self, wait: float = 0.0) -> bool:
        """Start the calibration process ahead of CALIBRATE (done by itself at 3 samples); True when ready."""
        return self.background.prepare(wait)

    def _calibrated(self, result) -> None:
        with self._lock:
            self.quality = None
        # the preview's maps are made here, in the calibration's thread: the frame loop never builds them
        self._preview.build(result, float(self.alpha.value), lambda: self.result)
        self.results.value = render.calibration_html(result, self.dropped, self._calibrating_from)
        self.commit_button.disabled = False

    def _failed(self, message: str) -> None:
        keep = " The previous calibration is kept." if self.result is not None else ""
        self.results.value = render.message_html(message + keep, "error")

    def _verdict(self, result, quality) -> None:
        """The verdict follows the result (it can take longer than the calibration)."""
        with self._lock:
            self.quality = quality
        verdict = verdict_html(quality)
        if verdict:
            self.results.value = render.calibration_html(result, self.dropped, self._calibrating_from, verdict)

    def _calibrate_ended(self) -> None:
        self.calibrate_button.disabled = not self.background.can_start()

    def camera(self) -> CameraModel | None:
        """The calibrated camera (``P`` with alpha 0, as ROS sets it), or None before CALIBRATE."""
        return self.session.camera

    def calibration(self) -> calib_files.IntrinsicCalibration | None:
        """The content of ``camera_intrinsic/<ROBOT>.yaml`` (None before CALIBRATE)."""
        return self.session.calibration()

    def _say(self, text: str, kind: str = "info") -> str:
        self.message.value = render.message_html(text, kind)
        return text

    def commit(self) -> str:
        """Write ``camera_intrinsic/<ROBOT>.yaml`` into the calibration folder and, with the
        target "robot over ROS", send it to ``/<ROBOT>/camera_node/set_camera_info``.

        The session's gate comes first, as for ``dtscal calibrate-intrinsics``: a calibration the kit
        does not believe is refused (nothing written, nothing sent); with "keep anyway" it is written as
        ``<ROBOT>.rejected.yaml`` beside the robot's file and never sent. On failure the message says
        why; the previous file on the robot or in the folder is unchanged, and SAVE still keeps the new
        calibration.
        """
        if self.result is None:
            return self._say("nothing to commit yet: CALIBRATE first", "error")
        keep = bool(self.keep_anyway.value)
        try:
            path = self.session.write(self.folder_text.value.strip(), keep_anyway=keep)
            if self.session.doubts:
                return self._say(f"COMMIT: kept as {path} beside the robot's file, against the kit's doubts: "
                                 + "; ".join(map(str, self.session.doubts)) + ". It is not sent to the robot.", "error")
            if self.commit_target.value == "folder":
                return self._say(f"COMMIT: wrote {path} (the previous file, if any, is kept as .bak)", "ok")
            answer = self.session.commit(master_uri=getattr(self.source, "master", None))
            return self._say(f"COMMIT to {self.robot}: {answer} (local copy: {path})", "ok")
        except ImplausibleCalibrationError as exc:
            doubts = "".join(f"<br>- {d}" for d in exc.doubts)
            return self._say(f"COMMIT refused: the kit does not believe this calibration, nothing was written "
                             f"and nothing sent:{doubts}<br>Collect more varied samples and CALIBRATE again, or, as "
                             f"an expert, tick \"keep anyway\" to keep it as {self.robot}"
                             f"{calib_files.REJECTED_SUFFIX}.yaml beside the robot's file.", "error")
        except (DtscalError, OSError) as exc:
            return self._say(f"COMMIT failed: {exc}. The previous calibration is unchanged; "
                             "SAVE still keeps this one.", "error")

    def save(self, path=None) -> str:
        """Write the samples (and the calibration, if any) into one zip archive."""
        path = Path(path or self.archive_text.value.strip() or f"{self.robot}_session.zip")
        if self.tracker is None:
            return self._say("nothing to save yet: no frame has arrived", "error")
        with self._lock:
            samples = list(self.tracker.samples)
        try:
            out = save_session(path, board=self.board, image_size=self.tracker.image_size, robot=self.robot,
                               samples=samples, calibration=self.calibration())
        except DtscalError as exc:
            return self._say(f"SAVE failed: {exc}", "error")
        return self._say(f"SAVE: {len(samples)} samples" + (" and the calibration" if self.result else "")
                         + f" in {out}", "ok")

    def load(self, path) -> str:
        """Replace the samples by those of a SAVE archive (CALIBRATE again to recalibrate)."""
        try:
            arch = load_session(path)
        except DtscalError as exc:
            return self._say(f"LOAD failed: {exc}", "error")
        if arch.board != self.board:
            return self._say(f"LOAD failed: the archive is for a {arch.board.describe()} board, this "
                             f"calibrator uses {self.board.describe()}", "error")
        with self._lock:
            if self.tracker is None or self.tracker.image_size != arch.image_size:
                self.tracker = CoverageTracker(self.board, arch.image_size)
            self.tracker.samples = list(arch.samples)
            self.thumbs = [render.outline_thumb(s.corners, arch.image_size) for s in arch.samples]
            bars, n = self.tracker.bars(), len(arch.samples)
        self.bars.value = render.bars_html(bars)
        self.count.value = f"samples: {n}"
        self._rebuild_thumbs()
        self.calibrate_button.disabled = not self.background.can_start()
        return self._say(f"loaded {n} samples from {path}; CALIBRATE to recalibrate", "ok")

    def reconnect(self) -> str:
        """Re-open the source; samples and calibration are kept."""
        try:
            self.loop.reconnect()
        except DtscalError as exc:
            return self._say(f"RECONNECT failed: {exc}", "error")
        return self._say(f"reconnecting to {self.spec}; {len(self.samples)} samples kept")

    def close(self) -> None:
        """Stop the frame loop, close the source and end the calibration process."""
        self.loop.close()
        self.background.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
