"""One calibration session: the one place where a calibration happens.

The command line (:mod:`dtscal_lib.cli`), the run over a recording (:mod:`dtscal_lib.pipeline`) and
the live tools (:mod:`dtscal_lib.ui`) are thin drivers of the same steps::

    session = IntrinsicSession(board, robot="autobot01")
    for frame in frames:
        session.offer(frame)          # detect the board, keep the view if it is new coverage
        if session.ready():           # ROS's rule: every bar full, or 40 samples
            break
    session.calibrate()               # the camera, views that fit far worse dropped
    session.judge()                   # the verdict's findings and the refusals, as Findings
    session.write("calibrations")     # camera_intrinsic/autobot01.yaml, or refused (nothing written)
    session.commit()                  # send it to the robot

:meth:`~IntrinsicSession.write` refuses what the kit does not believe
(:class:`~dtscal_lib.errors.ImplausibleCalibrationError`; nothing is written over the robot's file)
unless ``keep_anyway``, which writes ``ROBOT.rejected.yaml`` beside it; a refused result is never
sent to the robot. Every driver goes through this gate, so the live COMMIT refuses what
``dtscal calibrate-intrinsics`` refuses (exit code 3).

Layers: drivers (cli, pipeline, ui) call the session; the session calls the modules below it
(sources, detect and coverage, calibration, the judges quality / plausibility / ground, the file
formats calib_files, the robot); none of those calls back up (``tests/test_session.py`` traces it).
"""

from __future__ import annotations

import re
import tempfile
import threading
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from . import calib_files
from . import duckietown as dt
from .boards import DUCKIETOWN_BOARD, Board
from .calibration import CalibrationResult, calibrate
from .camera import CameraModel, as_size
from .coverage import CoverageTracker
from .detect import detect_board
from .errors import CalibrationError, DtscalError, ImplausibleCalibrationError, Reason, opencv_message
from .findings import Finding
from .limits import PATTERN_CONTINUES_SHARE, VIEW_OUTLIER_FACTOR

__all__ = ["IntrinsicSession", "ExtrinsicSession", "Offer", "FrameTally", "SizeGroups", "as_findings",
           "robot_from_topic", "robot_name", "camera_name", "intrinsic_file", "calibrate_without_outlier_views",
           "MIN_SAMPLES"]

#: fewer samples than this cannot give a trustworthy calibration
MIN_SAMPLES = 3
#: a view whose own reprojection RMS exceeds this many times the median view's is an outlier (the verdict's
#: value, one row of :mod:`dtscal_lib.limits`)
OUTLIER_FACTOR = VIEW_OUTLIER_FACTOR
#: never drop more than this share of the views as outliers
MAX_OUTLIER_SHARE = 0.2
#: frames without the declared board kept to name the board that is there, and how far from the declared
#: counts of inner corners the search goes (a 9x6 board declared 9x5, 10x6, 7x6 or 11x8 is named)
MISSED_KEPT = 4
SIZE_SEARCH = 2


# --------------------------------------------------------------------------- the robot's name: one rule
def robot_from_topic(topic: str | None) -> str | None:
    """``/autobot01/camera_node/image/compressed`` -> ``autobot01``."""
    if not topic:
        return None
    node = re.escape(dt.CAMERA_NODE).replace(re.escape("{robot}"), f"({calib_files.ROBOT_NAME.pattern})")
    m = re.match(rf"^{node}/", topic)
    return m.group(1) if m else None


def robot_name(spec=None, source=None, given: str | None = None) -> str | None:
    """The robot a calibration belongs to, or None when nothing tells.

    The one rule, in order: the name ``given`` (``--robot``, the UI's text field); ``ros:NAME``; the
    source's own ``robot``; the robot of its camera topic ``/NAME/camera_node/...``; for a ``.bag``
    path not yet opened, the robot of its camera topic. ``dtps:NAME...`` is a source with its ``robot``.
    """
    if given:
        return str(given).strip() or None
    text = "" if spec is None else str(spec)
    if text.startswith("ros:"):
        return text[4:].strip("/") or None
    if text.startswith("dtps:"):
        return re.split(r"[/@]", text[5:].strip(), maxsplit=1)[0] or None
    name = getattr(source, "robot", None) or robot_from_topic(getattr(source, "topic", None))
    if name is None and source is None and text.endswith(".bag"):
        try:
            from .sources import open_source

            name = robot_from_topic(open_source(text).topic)
        except DtscalError:
            name = None
    return name


def camera_name(robot: str) -> str:
    """The ``camera_name`` of a Duckiebot's intrinsic file: ``/ROBOT/camera_node``."""
    return dt.CAMERA_NODE.format(robot=robot)  # a fact, not a step of the walk (tests/test_session.py)


def intrinsic_file(camera: CameraModel, robot: str) -> calib_files.IntrinsicCalibration:
    """The content of ``camera_intrinsic/ROBOT.yaml`` for a calibrated camera (the one place it is made)."""
    return calib_files.IntrinsicCalibration.from_camera(camera, camera_name=camera_name(robot))


# --------------------------------------------------------------------------- findings
def as_findings(items, kind: str = "intrinsic") -> list[Finding]:
    """Refusals as :class:`~dtscal_lib.findings.Finding` s, whether a judge gave strings or Findings.

    The plausibility checks (:func:`~dtscal_lib.plausibility.intrinsic_doubts`,
    :func:`~dtscal_lib.ground.ground_homography_doubts`) are the refusals; a Finding is kept as it is,
    a bare string becomes a Finding of severity ``bad`` (a refusal's), code ``implausible_<kind>``.
    """
    out = []
    for item in items or ():
        if isinstance(item, Finding):
            out.append(item)
        else:
            out.append(Finding(f"implausible_{kind}", "bad", str(item), ""))
    return out


def _gate(session, *, writing: bool, keep_anyway: bool = False) -> tuple[str, list[Finding]]:
    """The one gate of WRITE and COMMIT: ``(robot, refusals)``, judged before any file or message.

    ``writing=False`` (only judging) accepts a missing robot name; a refused result raises
    :class:`~dtscal_lib.errors.ImplausibleCalibrationError` unless ``keep_anyway`` (never for COMMIT:
    its caller passes ``keep_anyway=False``)."""
    refusals = session.refusals() + _no_verdict(session)
    robot = calib_files.check_robot_name(session.robot) if writing else (session.robot or "camera")
    if refusals and not keep_anyway:
        raise _refusal(refusals, session.kind, robot)
    return robot, refusals


def _no_verdict(session) -> list[Finding]:
    """The verdict step, run before anything is written: a calibration whose verdict failed is refused."""
    verdict = getattr(session, "quality", None)
    q = verdict() if verdict is not None else None
    if not isinstance(q, str):
        return []
    return [Finding("no_verdict", "bad", f"the kit could not judge this calibration: {q}",
                    "report it with the recording; the camera computed is printed above")]


def _same_robot(link, robot: str):
    """The DTPS link of the robot the file is for (the session's name wins over the link's)."""
    import dataclasses

    return link if link.robot == robot else dataclasses.replace(link, robot=robot)


def _refusal(refusals, kind: str, robot: str) -> ImplausibleCalibrationError:
    doubts = list(refusals)
    listed = "".join(f"\n  - {d}" for d in doubts)
    where = f"camera_{kind}/{robot}.yaml"
    return ImplausibleCalibrationError(
        f"refusing to write {where}: the kit does not believe this {kind} calibration:{listed}\n"
        f"Nothing was written; the previous {where} (if any) is unchanged. Record again as described, or, as an "
        f"expert, rerun with keep_anyway=True to keep the result as camera_{kind}/{robot}"
        f"{calib_files.REJECTED_SUFFIX}.yaml beside it", doubts)


# --------------------------------------------------------------------------- frames
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

    def chosen(self) -> tuple[int, int] | None:
        if self.image_size is not None:
            return self.image_size
        if self.groups:
            return max(self.groups, key=lambda s: (self.groups[s].found, self.groups[s].tally.total))
        return None

    def resolve(self, tally: FrameTally) -> tuple[tuple[int, int], _SizeGroup] | None:
        """The calibration's size and its group; merges every group's counts into ``tally``."""
        size = self.chosen()
        if size is None:
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


@dataclass
class Offer:
    """What became of one offered frame: ``added`` as a sample, else ``reason``; ``detection`` if searched."""

    added: bool
    reason: str | None = None
    detection: object = None
    image: np.ndarray | None = None


def _image_of(frame, tally: FrameTally) -> tuple[np.ndarray | None, str | None]:
    """``(image, None)``, or ``(None, reason)`` (counted) for a frame that is no image."""
    tally.total += 1
    if isinstance(frame, np.ndarray):
        img, error = frame, None
    else:  # a source's Frame: one without an image always carries its FrameError (see errors.py)
        img, error = frame.image, frame.error
    if error is not None:
        reason = error.reason
    elif img is None:
        reason = Reason.UNREADABLE
    elif img.ndim < 2 or img.size == 0:
        reason = Reason.EMPTY
    else:
        return img, None
    tally.reject(reason)
    return None, reason


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
        if not worst:  # then single corners far off: named, left out, calibrated again
            return result.without_outlier_corners(), sorted(dropped)
        dropped += [keep[k] for k in worst]
        keep = [i for k, i in enumerate(keep) if k not in set(worst)]
        kept = [k for k in range(len(pv)) if k not in set(worst)]
        start = (result.K, result.dist, result.rvecs[kept], result.tvecs[kept])
        views = ([object_points[i] for i in keep], [image_points[i] for i in keep], image_size)
        try:
            result = calibrate(*views, initial=start, **kw)
        except CalibrationError:  # the warm start went astray: search from the closed form as the first fit did
            result = calibrate(*views, **kw)


def assess_quality(result):
    """The calibration's verdict, or its failure as a message (a str): the session's verdict step.

    Two steps: what the judge needs from the estimator (:func:`dtscal_lib.result.evidence`: the normal
    equations, the boards' tilt, a way to calibrate other views alike), then the judge
    (:func:`dtscal_lib.quality.assess`), which never calls back into the estimator. A failing verdict
    never loses the calibration: it becomes a message, and the session's gate refuses to write or commit a
    calibration without a verdict unless kept anyway (:func:`_gate`).
    """
    from .quality import assess
    from .result import evidence

    try:
        return assess(result, evidence(result))
    except Exception as exc:  # never lose the calibration: the gate refuses it, --keep-anyway keeps it
        return f"no verdict ({type(exc).__name__}: {exc})"


# --------------------------------------------------------------------------- intrinsics
class IntrinsicSession:
    """Frames in, ``camera_intrinsic/ROBOT.yaml`` out: offer, ready, calibrate, judge, write, commit.

    Parameters
    ----------
    board : the calibration board
    model, skew : the camera model (``plumb_bob`` or ``radial2``) and whether K's skew is estimated
    robot : the robot whose file is written (:func:`robot_name`); settable until :meth:`write`
    image_size : the frames to calibrate; by default the size in which the board is found most
        often. ``first_size_wins`` (a live camera) fixes it from the first frame instead.
    stream : frames of a stream keep only new coverage (ROS's rule); stills keep every view found
    source : a description of the frames, for messages
    """

    kind = "intrinsic"

    def __init__(self, board: Board = DUCKIETOWN_BOARD, *, model: str = "plumb_bob", skew: bool = False,
                 robot: str | None = None, image_size=None, stream: bool = True, first_size_wins: bool = False,
                 source: str = "the frames"):
        self.board, self.model, self.skew, self.robot = board, model, skew, robot
        self.stream, self.first_size_wins, self.source = stream, first_size_wins, source
        self.requested_size = None if image_size is None else tuple(image_size)
        self.groups = SizeGroups(board, image_size)
        self.lock = threading.RLock()
        self._frames = FrameTally()  # frames that are no image, and those a source skipped
        self.result: CalibrationResult | None = None
        #: the calibrated camera (``P`` with alpha 0, as ROS sets it), None before CALIBRATE
        self.camera: CameraModel | None = None
        self.dropped: list[int] = []
        self.path: Path | None = None
        self._kept_points: list = []
        self._bars: list = []
        self._quality = None
        self._refusals: list[Finding] | None = None
        #: found detections by the bigger pattern the saddles showed around them (None: the declared size)
        self._patterns: Counter = Counter()
        #: a few frames where the declared board was not found (spread over the run), to name the board that is there
        self._missed: list = []
        self._n_missed = 0

    # ---- frames
    def offer(self, frame) -> Offer:
        """Search a frame (a source's Frame, or an image) for the board; keep it if it is a new view."""
        with self.lock:
            img, reason = _image_of(frame, self._frames)
        if img is None:
            return Offer(False, reason)
        with self.lock:
            size = (int(img.shape[1]), int(img.shape[0]))
            if self.first_size_wins and self.groups.image_size is None:
                self.groups.image_size = size
            group = self.groups.group(img)
            group.tally.total += 1
            if self.groups.image_size not in (None, size):
                return Offer(False, Reason.SIZE_MISMATCH, None, img)  # counted at the end, by resolve
        try:
            det = detect_board(img, self.board)
        except DtscalError as exc:  # a frame the detector cannot take: count it, go on
            reason = exc.reason or Reason.BAD_FRAME
            group.tally.reject(reason)
            return Offer(False, reason, None, img)
        except cv2.error:  # OpenCV choking on one odd frame must not end the run
            group.tally.reject(Reason.DETECTOR_ERROR)
            return Offer(False, Reason.DETECTOR_ERROR, None, img)
        if not det.found:
            reason = det.reason or Reason.NO_BOARD
            group.tally.reject(reason)
            self._keep_missed(img)
            return Offer(False, reason, det, img)
        with self.lock:
            group.found += 1
            self._patterns[det.pattern_seen] += 1
            index = getattr(frame, "index", None)
            if self.stream:
                added = group.tracker.offer(det, index)
                if added:
                    group.tally.used += 1
                else:
                    group.tally.reject(Reason.NOT_NEW_COVERAGE)
                return Offer(added, None if added else Reason.NOT_NEW_COVERAGE, det, img)
            group.tracker.offer(det)  # keeps the bars meaningful for stills too
            obj = self.board.object_points()
            group.obj.append(obj if det.ids is None else obj[det.ids])  # a ChArUco view: the corners seen
            group.img.append(det.corners)
            group.tally.used += 1
            return Offer(True, None, det, img)

    def _check_board_size(self) -> None:
        """Refuse, in words, a board declared smaller than it is: in most views the saddles continue past the
        declared corners as equally strong corners (:attr:`~dtscal_lib.detect.Detection.pattern_seen`), so
        each view is a sub-grid found somewhere on the board and the calibration would be nonsense."""
        with self.lock:
            found = sum(self._patterns.values())
            bigger = [(n, size) for size, n in self._patterns.items() if size is not None]
        if not bigger or found < 2:
            return
        n, (cols, rows) = max(bigger)
        if n >= PATTERN_CONTINUES_SHARE * found:
            raise CalibrationError(
                f"the pattern continues past the declared corners: in {n} of the {found} views where the declared "
                f"{self.board.cols}x{self.board.rows} board was found, the board's corners go on beyond it "
                f"({cols}x{rows} inner corners are seen), so each view would be a part of the board found at some "
                f"place on it and the calibration meaningless. Nothing was calibrated: pass --board {cols}x{rows} "
                "(count the inner corners, where four squares meet)", reason=Reason.BOARD_SIZE)

    def _keep_missed(self, img) -> None:
        """Keep at most :data:`MISSED_KEPT` frames without the declared board, spread over the run (the 1st, 2nd,
        4th, 8th, ... missed frame), for :meth:`_board_there`."""
        with self.lock:
            self._n_missed += 1
            n = self._n_missed
            if n & (n - 1) == 0:  # a power of two
                self._missed = (self._missed + [img])[-MISSED_KEPT:]

    def _board_there(self) -> tuple[int, int] | None:
        """The board size (inner corners) the missed frames show, when the declared one was never found.

        Sizes near the declared one (each count within :data:`SIZE_SEARCH` of it, either way round) are looked
        for with the kit's detector, the nearest first; a size found in a frame is the answer, or the larger
        pattern its saddles continue into (:attr:`~dtscal_lib.detect.Detection.pattern_seen`).
        """
        with self.lock:
            frames = list(self._missed)
        c0, r0 = self.board.cols, self.board.rows
        sizes = {(c, r) for c in range(c0 - SIZE_SEARCH, c0 + SIZE_SEARCH + 1)
                 for r in range(r0 - SIZE_SEARCH, r0 + SIZE_SEARCH + 1) if c >= 3 and r >= 3 and c != r}
        sizes |= {(r, c) for c, r in sizes}
        sizes.discard((c0, r0))
        def order(cr):  # nearest the declared first, the declared way round, the larger
            return abs(cr[0] - c0) + abs(cr[1] - r0), (cr[0] > cr[1]) != (c0 > r0), -cr[0] * cr[1]

        for cols, rows in sorted(sizes, key=order):
            for img in frames:
                try:
                    det = detect_board(img, Board(cols, rows, self.board.square))
                except (DtscalError, cv2.error):
                    continue
                if det.found:
                    return det.pattern_seen or (cols, rows)
        return None

    def skipped(self, counts) -> None:
        """Count frames a source skipped itself (corrupt frames of a live camera), by reason."""
        self._frames.rejected.update(dict(counts or {}))

    @property
    def tracker(self) -> CoverageTracker | None:
        """The coverage of the calibration's image size (None before the first frame)."""
        with self.lock:
            size = self.groups.chosen()
            group = self.groups.groups.get(size) if size is not None else None
            return None if group is None else group.tracker

    @tracker.setter
    def tracker(self, tracker: CoverageTracker | None) -> None:
        """Replace the samples (a loaded archive, a test): the tracker's size becomes the calibration's."""
        with self.lock:
            if tracker is None:
                self.groups.groups.clear()
                self.groups.image_size = self.requested_size
                return
            self.groups.image_size = tuple(tracker.image_size)
            self.groups.groups[self.groups.image_size] = _SizeGroup(tracker)

    def ready(self) -> bool:
        """True once ROS's coverage rule enables CALIBRATE (every bar full, or 40 samples)."""
        with self.lock:
            return self.groups.ready()

    def tally(self) -> FrameTally:
        """How the frames were used so far (views dropped as outliers by the last calibration included)."""
        with self.lock:
            out = FrameTally(self._frames.total, self._frames.used, Counter(self._frames.rejected))
            self.groups.resolve(out)
            if self.dropped:
                out.used -= len(self.dropped)
                out.rejected[Reason.OUTLIER_VIEW] += len(self.dropped)
            return out

    def views(self):
        """``(object_points, image_points, image_size)`` of the kept views, as they are now."""
        with self.lock:
            size = self.groups.chosen()
            group = self.groups.groups.get(size) if size is not None else None
            if group is None:
                return [], [], size
            if self.stream:
                obj, img = group.tracker.object_and_image_points()
            else:
                obj, img = list(group.obj), list(group.img)
            return obj, img, size

    def _bars_now(self) -> list:
        tracker = self.tracker
        return [] if tracker is None else tracker.bars()

    def bars(self) -> list:
        """The coverage bars (X, Y, Size, Skew): of the views the last calibration used, else as they are now."""
        return self._bars if self.result is not None else self._bars_now()

    # ---- calibrate
    def calibrate(self, solver=None) -> CalibrationResult:
        """Calibrate from the kept views (views that fit far worse dropped); raises with what to do.

        ``solver`` (optional) computes ``calibrate_without_outlier_views`` elsewhere (the live tool's
        helper process): an object with ``calibrate(obj, img, size, model, skew=...) -> (result, dropped)``.
        """
        obj, img, size = self.views()
        bars = self._bars_now()
        tally = self.tally()
        if size is None or (self.groups.image_size is not None and size not in self.groups.groups):
            if self.groups.groups and self.groups.image_size is not None:
                seen = ", ".join(f"{w}x{h}" for w, h in self.groups.groups)
                raise DtscalError(f"{self.source}: no frame has the requested image size {size[0]}x{size[1]} "
                                  f"(sizes found: {seen}); pass the size of the camera's frames")
            raise DtscalError(f"{self.source}: no readable frame ({tally.total} frames, rejected: "
                              f"{dict(tally.rejected) or 'none'}); check the path and the topic")
        if len(obj) < MIN_SAMPLES:
            there = self._board_there()
            if there is not None:
                raise CalibrationError(
                    f"the declared {self.board.cols}x{self.board.rows} board was never found in {self.source} "
                    f"({tally.total} frames), but a {there[0]}x{there[1]} board (inner corners) is there. Nothing was "
                    f"calibrated: pass --board {there[0]}x{there[1]} (count the inner corners, where four squares "
                    "meet)", reason=Reason.BOARD_SIZE)
            raise CalibrationError(
                f"only {len(obj)} usable view(s) of the {self.board.describe()} board in {self.source} "
                f"({tally.total} frames; rejected: {dict(tally.rejected)}). Calibration needs at least "
                f"{MIN_SAMPLES} views at different positions and tilts: check --board/--square, and show the "
                "whole board (not touching the image border) at several places and angles")
        self._check_board_size()
        if solver is not None:
            result, dropped = solver.calibrate(obj, img, size, self.model, skew=self.skew)
        else:
            result, dropped = calibrate_without_outlier_views(obj, img, size, model=self.model, skew=self.skew)
        if not np.all(np.isfinite(result.K)):
            raise CalibrationError("the calibration did not converge; collect more varied samples")
        gone = set(dropped)
        camera = result.camera()
        with self.lock:
            self.result, self.camera, self.dropped, self._bars = result, camera, list(dropped), bars
            self._kept_points = [p for i, p in enumerate(img) if i not in gone]
            self._quality, self._refusals, self.path = None, None, None
        return result

    # ---- judge
    def refusals(self) -> list[Finding]:
        """Why the kit does not believe the calibration (the plausibility checks); empty: believable."""
        from .plausibility import intrinsic_doubts

        with self.lock:
            result, cached, points = self.result, self._refusals, self._kept_points
        if result is None:
            raise DtscalError("nothing to judge yet: CALIBRATE first")
        if cached is None:
            cached = as_findings(intrinsic_doubts(result, points), self.kind)
            with self.lock:
                if self.result is result:
                    self._refusals = cached
        return cached

    @property
    def doubts(self) -> list[Finding]:
        """The refusals (empty before CALIBRATE and for a believable result); ``str()`` of each says what to do."""
        return [] if self.result is None else list(self.refusals()) + _no_verdict(self)

    def quality(self, known=None):
        """The verdict (:class:`~dtscal_lib.quality.Quality`, or a message when it cannot be made).

        ``known``: a verdict computed elsewhere for the current result (the live tool's helper process).
        """
        with self.lock:
            result = self.result
            if known is not None and result is not None:
                self._quality = known
            if self._quality is not None or result is None:
                return self._quality
        q = assess_quality(result)
        with self.lock:
            if self.result is result:
                self._quality = q
        return q

    def judge(self) -> list[Finding]:
        """Verdict and refusals together: the verdict's findings, then the refusals (:meth:`refusals`, the
        plausibility doubts). A result with refusals is not written unless kept anyway."""
        q = self.quality()
        return (list(q.findings) if not isinstance(q, str) else _no_verdict(self)) + self.refusals()

    # ---- write, commit
    def calibration(self) -> calib_files.IntrinsicCalibration | None:
        """The content of the robot's intrinsic file (None before CALIBRATE)."""
        if self.result is None:
            return None
        return intrinsic_file(self.camera, self.robot or "camera")

    def write(self, out, keep_anyway: bool = False, fmt: str = "classic") -> Path | None:
        """Write ``out/camera_intrinsic/ROBOT.yaml`` (previous one kept as ``.bak``), the kit's gate first.

        A result with refusals raises :class:`~dtscal_lib.errors.ImplausibleCalibrationError` and
        writes nothing; ``keep_anyway`` writes it as ``ROBOT.rejected.yaml`` beside the robot's file.
        ``out=None`` only judges (and writes nothing). Returns the path written.
        """
        if fmt != "classic":
            raise DtscalError(f"intrinsic files have one format (classic), not {fmt!r}")
        if self.result is None:
            raise DtscalError("nothing to write yet: CALIBRATE first")
        robot, refusals = _gate(self, writing=out is not None, keep_anyway=keep_anyway)
        if out is None:
            return None
        self.path = calib_files.save_intrinsics(self.calibration(), out, robot, rejected=bool(refusals),
                                                uncertainty=self.file_uncertainty())
        return self.path

    def file_uncertainty(self):
        """The σ the written file carries (:mod:`dtscal_lib.file_uncertainty`); None for OpenCV's models, or
        when it cannot be computed (the file is then written without it, as ROS writes it)."""
        from . import file_uncertainty

        try:
            unc = file_uncertainty.from_result(self.result)
        except (DtscalError, np.linalg.LinAlgError):
            return None
        return None if unc is None or unc.mismatch(self.calibration()) else unc

    def commit(self, *, master_uri: str | None = None, timeout: float | None = None, dtps=None) -> str:
        """Send the calibration to the robot (the written file, or a temporary one): over DTPS to its key-value
        store when ``dtps`` (a :class:`~dtscal_lib.dtps_link.DtpsRobot`) is given, else over ROS 1 to its camera
        node's ``set_camera_info`` (:mod:`dtscal_lib.robot`).

        A result the kit refuses is never sent, even when kept anyway (raises ImplausibleCalibrationError).
        """
        from . import robot as robot_link

        if self.result is None:
            raise DtscalError("nothing to commit yet: CALIBRATE first")
        robot, _ = _gate(self, writing=True)
        path = self.path or calib_files.save_intrinsics(self.calibration(), tempfile.mkdtemp(prefix="dtscal-commit-"),
                                                        robot)
        kw = {} if timeout is None else {"timeout": timeout}
        if dtps is not None:
            return robot_link.commit_dtps(_same_robot(dtps, robot), path, kind="camera_intrinsic", **kw)
        return robot_link.commit_intrinsics(robot, path, master_uri=master_uri, **kw)


# --------------------------------------------------------------------------- extrinsics
class ExtrinsicSession:
    """Frames of the robot on the board in, ``camera_extrinsic/ROBOT.yaml`` out.

    Each offered frame is fitted (:func:`~dtscal_lib.ground.extrinsics_from_image`); the session keeps
    the first fit (``keep="first"``, Duckietown's procedure on a recording) or the best so far
    (``keep="best"``, the live tool). ``camera`` is settable (a new intrinsic calibration: the fits
    made with the old one are forgotten). ``intrinsics`` (an IntrinsicCalibration or a path) is needed
    for the version-2 file; by default it is made from ``camera``.
    """

    kind = "extrinsic"

    def __init__(self, camera: CameraModel | None, board: Board = DUCKIETOWN_BOARD, *, robot: str | None = None,
                 keep: str = "first", intrinsics=None, source: str = "the frames", profile=None):
        from .profiles import profile_for

        self.board, self.robot, self.keep, self.intrinsics, self.source = board, robot, keep, intrinsics, source
        #: the robot the board lies in front of (:mod:`dtscal_lib.profiles`; by default the one the board implies)
        self.profile = profile or profile_for(board)
        #: the camera whose rectified image the homography maps (settable: a new intrinsic calibration)
        self.camera = camera
        self.lock = threading.RLock()
        self._tally = FrameTally()
        self.best = None
        self.best_frame = -1
        self.last_error = None
        self.path: Path | None = None

    def forget(self) -> None:
        """Forget the best fit (the robot moved, or a new intrinsic calibration)."""
        with self.lock:
            self.best, self.best_frame, self.path = None, -1, None

    def offer(self, frame, camera: CameraModel | None = None) -> Offer:
        """Fit the ground homography on one frame; ``detection`` of the Offer is the fit (None on failure).

        ``camera`` overrides the session's for this frame (the same camera with its maps made once).
        """
        from .ground import extrinsics_from_image

        img, reason = _image_of(frame, self._tally)
        if img is None:
            return Offer(False, reason)
        cam = camera or self.camera
        if cam is None:
            raise DtscalError("no intrinsic calibration yet: CALIBRATE the intrinsics first")
        try:
            res = extrinsics_from_image(img, cam, self.board, profile=self.profile)
        except DtscalError as exc:  # counted under the frame's own reason (size, NaN, board, homography)
            reason = exc.reason or Reason.HOMOGRAPHY_FAILED
            self._tally.reject(reason)
            self.last_error = exc
            return Offer(False, reason, None, img)
        except cv2.error as exc:  # OpenCV choking on one odd frame must not end the run
            self._tally.reject(Reason.DETECTOR_ERROR)
            self.last_error = opencv_message(exc)
            return Offer(False, Reason.DETECTOR_ERROR, None, img)
        self._tally.used += 1
        err = float(np.mean(res.residual_mm))
        with self.lock:
            better = self.best is None or (self.keep == "best" and err < float(np.mean(self.best.residual_mm)))
            if better:
                self.best, self.best_frame, self.path = res, getattr(frame, "index", -1), None
        return Offer(better, None, res, img)

    def tally(self) -> FrameTally:
        """How the frames were used so far."""
        return self._tally

    def ready(self) -> bool:
        """True once a frame gave a fit."""
        return self.best is not None

    def calibrate(self):
        """The kept fit (:class:`~dtscal_lib.ground.ExtrinsicResult`); raises with what to do if none."""
        with self.lock:
            best = self.best
        if best is None:
            last = self.last_error
            raise CalibrationError(
                f"no frame of {self.source} gave a ground homography ({self._tally.total} frames; rejected: "
                f"{dict(self._tally.rejected)})" + (f"; last problem: {last}" if last else "")
                + ". Place the robot on the board as in the Duckietown procedure, with the whole board in view")
        return best

    def camera_pose(self) -> dict:
        """The camera's height and pitch recovered from the kept homography."""
        from .ground import camera_pose_from_homography

        return camera_pose_from_homography(self.calibrate().H, self.camera.P[:, :3], self.profile.near_row_x)

    def refusals(self) -> list[Finding]:
        """Why the kit does not believe the homography (a camera looking down at the ground ahead?)."""
        from .ground import ground_homography_doubts

        res = self.calibrate()
        return as_findings(ground_homography_doubts(res.H, self.camera.P[:, :3], board=self.board,
                                                    pattern_contrast=getattr(res, "pattern_contrast", None),
                                                    profile=self.profile,
                                                    upside_down=getattr(res, "upside_down", False)),
                           self.kind)

    @property
    def doubts(self) -> list[Finding]:
        return [] if self.best is None else list(self.refusals())

    def judge(self) -> list[Finding]:
        """The refusals (a homography has no verdict beyond its corner residuals, reported with it)."""
        return self.refusals()

    def _intrinsics(self):
        if self.intrinsics is not None:
            return self.intrinsics
        return intrinsic_file(self.camera, self.robot or "camera")

    def write(self, out, keep_anyway: bool = False, fmt: str = "classic") -> Path | None:
        """Write ``out/camera_extrinsic/ROBOT.yaml`` (classic or version ``"2"``), the kit's gate first.

        As :meth:`IntrinsicSession.write`: refused (nothing written) unless ``keep_anyway``, which writes
        ``ROBOT.rejected.yaml`` beside the robot's file, in the format asked for.
        """
        res = self.calibrate()
        robot, refusals = _gate(self, writing=out is not None, keep_anyway=keep_anyway)
        if out is None:
            return None
        intrinsics = self._intrinsics() if fmt == "2" else None
        self.path = calib_files.save_extrinsics_as(res.H, out, robot, fmt=fmt, intrinsics=intrinsics,
                                                   rejected=bool(refusals), corrupt_rule=self.profile.corrupt_rule)
        return self.path

    def commit(self, *, master_uri: str | None = None, timeout: float | None = None, url: str | None = None,
               fmt: str = "classic", dtps=None) -> str:
        """Upload the extrinsic file to the robot (the written file, or a temporary one in ``fmt``): over DTPS
        to its key-value store when ``dtps`` is given, else to its file server (:mod:`dtscal_lib.robot`).

        A result the kit refuses is never sent, even when kept anyway (raises ImplausibleCalibrationError).
        """
        from . import robot as robot_link

        res = self.calibrate()
        robot, _ = _gate(self, writing=True)
        path = self.path or calib_files.save_extrinsics_as(
            res.H, tempfile.mkdtemp(prefix="dtscal-commit-"), robot, fmt=fmt,
            intrinsics=self._intrinsics() if fmt == "2" else None, corrupt_rule=self.profile.corrupt_rule)
        kw = {} if timeout is None else {"timeout": timeout}
        if dtps is not None:
            return robot_link.commit_dtps(_same_robot(dtps, robot), path, kind="camera_extrinsic", **kw)
        return robot_link.commit_extrinsics(robot, path, master_uri=master_uri, url=url, **kw)
