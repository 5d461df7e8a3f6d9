"""One calibration session behind the command line, the pipeline and the live tools (issue 15).

* The live COMMIT refuses what ``dtscal calibrate-intrinsics`` refuses: three near-parallel views of
  the board make the command exit 3 and write nothing; the live calibrator, given the same three
  views, refuses to COMMIT (nothing written, nothing sent) and keeps the result beside the robot's
  file only with the same expert override (``keep anyway``), never sending it to the robot.
* ``calibrate-extrinsics --format 2 --keep-anyway`` writes the rejected file beside, in version 2
  (it used to print "nothing written (--no-write)" without ``--no-write``).
* The walk of a frame to a committed file, traced call by call (docstring of
  :func:`test_the_walk_visits_each_module_once_and_the_live_tool_walks_the_same_session`), into a
  calibrations folder and (slow: a private ``roscore`` and a camera node) to the robot over ROS.
* The library does not import the teaching layer ``dtscal_lib/teaching/course``.
"""

from __future__ import annotations

import subprocess
import sys
import threading
from pathlib import Path

import cv2
import numpy as np
import pytest

from dtscal_lib import calib_files, datasets, pipeline, synth
from dtscal_lib.boards import DUCKIETOWN_BOARD
from dtscal_lib.errors import ImplausibleCalibrationError
from dtscal_lib.session import IntrinsicSession, as_findings, robot_name
from dtscal_lib.sources import open_source, write_compressed_image_bag
from dtscal_lib.sources.frame import Frame

SESSION = datasets.session_dir()
INTRINSIC_BAG = SESSION / "intrinsics.bag"
LIB = Path(pipeline.__file__).resolve().parent
REFUSED = 3
#: three board poses (rvec, tvec) whose normals lie within 5.5 degrees of their mean: the plausibility
#: check asks for 10 (dtscal_lib.plausibility), so the kit refuses the calibration they give
NEAR_PARALLEL = [([0.08, 0.02, 0.0], [-0.22, -0.12, 0.36]), ([0.0, 0.09, 0.05], [-0.05, -0.02, 0.40]),
                 ([-0.06, -0.05, -0.04], [0.02, -0.16, 0.30])]


def dtscal(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "dtscal_lib.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=600, check=False)


def files_under(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file()) if folder.exists() else []


@pytest.fixture(scope="module")
def parallel_views(tmp_path_factory) -> Path:
    """The three near-parallel views, rendered by the kit's simulated camera as PNG files."""
    folder = tmp_path_factory.mktemp("parallel")
    cam = synth.synthetic_camera()
    for i, (r, t) in enumerate(NEAR_PARALLEL):
        img, _, visible = synth.render_view(cam, DUCKIETOWN_BOARD, np.array(r), np.array(t),
                                            rng=np.random.default_rng(i))
        assert visible
        cv2.imwrite(str(folder / f"view_{i}.png"), img)
    return folder


def test_cli_refuses_three_near_parallel_views_and_writes_nothing(parallel_views, tmp_path):
    out = tmp_path / "calibrations"
    p = dtscal("calibrate-intrinsics", "--source", parallel_views, "--robot", "bot", "--out", out, "-q")
    assert p.returncode == REFUSED, p.stderr
    assert "refusing to write camera_intrinsic/bot.yaml" in p.stderr and "tilted too little" in p.stderr
    assert files_under(out) == []


def test_live_commit_refuses_what_the_cli_refuses(parallel_views, tmp_path, monkeypatch):
    """The same three views in the live calibrator: COMMIT refuses (nothing written, nothing sent);
    "keep anyway" writes bot.rejected.yaml beside the robot's file and still sends nothing."""
    from dtscal_lib import robot as robot_link
    from dtscal_lib.ui import LiveCalibrator

    sent = []
    monkeypatch.setattr(robot_link, "commit_intrinsics", lambda *a, **k: sent.append(a) or "sent")
    app = LiveCalibrator(str(INTRINSIC_BAG), autostart=False, calibration_dir=tmp_path)
    try:
        app.robot_text.value = "bot"
        for i, path in enumerate(sorted(parallel_views.glob("*.png"))):
            app.loop.step(Frame(i, 0.0, cv2.imread(str(path)), None, path.name))
        assert len(app.samples) == 3
        assert app.calibrate(wait=True) is not None, app.calibrate_error
        assert app.session.doubts and any("tilted too little" in d for d in app.session.doubts)
        for target in ("folder", "ros"):
            app.commit_target.value = target
            msg = app.commit()
            assert msg.startswith("COMMIT refused") and "tilted too little" in msg, msg
            assert "keep anyway" in msg and "dtscal-error" in app.message.value
            assert files_under(tmp_path) == [] and sent == []
        app.keep_anyway.value = True  # the expert override, as --keep-anyway
        msg = app.commit()
        assert "kept as" in msg and "not sent to the robot" in msg, msg
        assert files_under(tmp_path) == ["camera_intrinsic/bot.rejected.yaml"] and sent == []
        kept = calib_files.load_intrinsics(tmp_path / "camera_intrinsic" / "bot.rejected.yaml")
        np.testing.assert_allclose(kept.K, app.result.K)
    finally:
        app.close()


def test_the_library_refuses_the_same_views_through_the_session(parallel_views, tmp_path):
    session = IntrinsicSession(DUCKIETOWN_BOARD, robot="bot", stream=False)
    for f in open_source(parallel_views):
        session.offer(f)
    session.calibrate()
    judged = session.judge()
    refusals = session.refusals()
    assert refusals and refusals == session.doubts and judged[-len(refusals):] == refusals
    assert len(judged) > len(refusals)  # the verdict's findings come first, in the same list
    with pytest.raises(ImplausibleCalibrationError):
        session.write(tmp_path)
    with pytest.raises(ImplausibleCalibrationError):
        session.commit()
    assert files_under(tmp_path) == []


def test_findings_adapter_takes_strings_and_findings():
    from dtscal_lib.findings import Finding

    f = Finding("x", "bad", "m", "a")
    out = as_findings(["a doubt", f], "intrinsic")
    assert out[1] is f and str(out[0]) == "a doubt" and out[0].severity == "bad"
    assert out[0].code == "implausible_intrinsic"


def test_format_2_with_keep_anyway_writes_the_rejected_file_beside(tmp_path):
    """The hand-held intrinsic recording gives a homography the kit refuses (camera not above the ground)."""
    out = tmp_path / "calibrations"
    calib_files.write_defaults(out)
    intr = calib_files.intrinsic_path(out, "default")
    before = files_under(out)
    p = dtscal("calibrate-extrinsics", "--source", INTRINSIC_BAG, "--intrinsics", intr, "--out", out, "-q",
               "--format", "2", "--keep-anyway")
    assert p.returncode == REFUSED, p.stderr
    kept = out / "camera_extrinsic" / "synthbot.rejected.yaml"
    assert "nothing written" not in p.stderr and f"kept as {kept}" in p.stderr
    assert files_under(out) == sorted(before + ["camera_extrinsic/synthbot.rejected.yaml"])
    _, fmt, _ = calib_files.read_extrinsic_file(kept, intrinsics=intr)
    assert fmt == "2"


def test_one_robot_name_rule():
    assert robot_name("ros:autobot01") == "autobot01"
    assert robot_name("x.bag", None, "given") == "given"
    assert robot_name(INTRINSIC_BAG) == "synthbot"  # from the bag's camera topic
    assert robot_name("device:0") is None


# --------------------------------------------------------------------------- the walk
#: the layers of a calibration's walk: drivers call the session, the session calls the areas below
DRIVERS = {"cli", "pipeline", "ui.intrinsic", "ui.intrinsic_driver", "ui.extrinsic", "ui.extrinsic_driver",
           "ui.background", "ui.frameloop", "ui.render", "ui.archive"}
DETECT = {"detect", "detect.classic", "detect.frame", "detect.grid", "detect.lattice", "detect.order", "detect.refine",
          "detect.saddles"}
AREAS = {"detect": DETECT | {"coverage", "boards"},
         "calibration": {"calibration", "closed_form", "lsq", "result", "camera", "ui.solver"},
         "judge": {"plausibility", "quality", "ground", "report"},
         "files": {"calib_files", "safe_yaml", "file_uncertainty"}, "robot": {"robot"}}
#: the steps of a calibration: only the session calls them
STEPS = {("detect.classic", "detect_board"), ("calibration", "calibrate"), ("plausibility", "intrinsic_doubts"),
         ("quality", "assess"), ("calib_files", "save_intrinsics"), ("robot", "commit_intrinsics")}


def _module(filename: str) -> str | None:
    try:
        rel = Path(filename).resolve().relative_to(LIB)
    except ValueError:
        return None
    return ".".join(rel.with_suffix("").parts)


class Walk:
    """Every call from one dtscal_lib module into another (``sys.settrace`` and ``threading.settrace``)."""

    def __init__(self):
        self.edges: list[tuple[str, str, str]] = []  # (caller module, callee module, callee function)
        self._modules: dict[str, str | None] = {}

    def module(self, filename):
        if filename not in self._modules:
            self._modules[filename] = _module(filename)
        return self._modules[filename]

    def trace(self, frame, event, arg):
        if event == "call":
            callee = self.module(frame.f_code.co_filename)
            if callee is not None:
                back = frame.f_back
                while back is not None and self.module(back.f_code.co_filename) is None:
                    back = back.f_back  # through Python's own frames (functools, threading, ...)
                caller = None if back is None else self.module(back.f_code.co_filename)
                if caller is not None and caller != callee:
                    self.edges.append((caller, callee, frame.f_code.co_name))
        return None

    def __enter__(self):
        threading.settrace(self.trace)
        sys.settrace(self.trace)
        return self

    def __exit__(self, *exc):
        sys.settrace(None)
        threading.settrace(None)

    @staticmethod
    def layer(module: str) -> int:
        return 2 if module in DRIVERS else 1 if module == "session" else 0

    @staticmethod
    def area(module: str) -> str:
        return next((a for a, mods in AREAS.items() if module in mods), module)

    def climbs(self) -> list[tuple[str, str, str]]:
        return [e for e in self.edges if self.layer(e[0]) < self.layer(e[1])]

    def session_walk(self) -> list[str]:
        """The areas the session enters, in order, consecutive repeats folded (the frame loop is one visit)."""
        out: list[str] = []
        for caller, callee, _ in self.edges:
            if caller == "session" and callee != "errors":
                a = self.area(callee)
                if not out or out[-1] != a:
                    out.append(a)
        return out

    def callbacks(self) -> list[tuple[str, str]]:
        """Pairs of modules below the session that call each other: (A, B) when A calls B and B calls A."""
        below = {(a, b) for a, b, _ in self.edges if self.layer(a) == 0 and self.layer(b) == 0}
        return sorted((a, b) for a, b in below if (b, a) in below and a < b)

    def judge_calls_back(self) -> list[tuple[str, str, str]]:
        """Calls from the judge (quality, rules, uncertainty) into the estimator (calibration, result, lsq,
        closed_form), except the refit the session handed it (``calibrate``, through ``Evidence.refit``)."""
        judge, estimator = {"quality", "rules", "uncertainty"}, {"calibration", "result", "lsq", "closed_form"}
        return [e for e in self.edges if e[0] in judge and e[1] in estimator and e[2] != "calibrate"]

    def steps_called_by(self) -> dict[tuple[str, str], set[str]]:
        out: dict = {}
        for caller, callee, fn in self.edges:
            if (callee, fn) in STEPS:
                out.setdefault((callee, fn), set()).add(caller)
        return out


@pytest.fixture(scope="module")
def short_bag(tmp_path_factory) -> Path:
    """Every 15th frame of the shipped intrinsic recording (28 frames; a believable calibration)."""
    frames = [(stamp, data) for i, (stamp, _, data) in enumerate(datasets.read_bag_jpegs(INTRINSIC_BAG))
              if i % 15 == 0]
    return write_compressed_image_bag(tmp_path_factory.mktemp("walk") / "walk.bag",
                                      "/walkbot/camera_node/image/compressed", frames)


def walk_the_live_calibrator(bag: Path, folder: Path, target: str) -> tuple[Walk, str]:
    """Frames of ``bag`` stepped into the live calibrator, CALIBRATE, COMMIT to ``target``, traced."""
    from dtscal_lib.ui import LiveCalibrator

    app = LiveCalibrator(str(bag), autostart=False, calibration_dir=folder)
    try:
        frames = [f for f in open_source(bag) if f.ok]
        app.prepare_calibration = lambda wait=0.0: False  # CALIBRATE in this process, where it is traced
        with Walk() as walk:
            for f in frames:
                app.loop.step(f)
            assert app.calibrate(wait=True) is not None, app.calibrate_error
            app.commit_target.value = target
            msg = app.commit()
    finally:
        app.close()
    return walk, msg


def check_walk(walk: Walk, areas: list[str], steps: list[tuple[str, str]]) -> None:
    """No climb, no call back (a module below the session never calls a module that called it); the session
    enters ``areas`` in that order, each once; ``steps`` are called by the session only."""
    assert walk.climbs() == []
    assert walk.callbacks() == []
    assert walk.judge_calls_back() == []  # the judge gets what it needs passed in (dtscal_lib.result.evidence)
    assert walk.session_walk() == areas
    called = walk.steps_called_by()
    for step in steps:
        assert called.get(step) == {"session"}, (step, called.get(step))


#: the steps of every walk, and of a walk that ends on the robot
FOLDER_STEPS = [("detect.classic", "detect_board"), ("calibration", "calibrate"), ("plausibility", "intrinsic_doubts"),
                ("calib_files", "save_intrinsics")]
ROBOT_STEPS = FOLDER_STEPS + [("robot", "commit_intrinsics")]


def test_the_walk_visits_each_module_once_and_the_live_tool_walks_the_same_session(short_bag, tmp_path):
    """Reading of "a walk of one bag frame to a committed file visits each module once (no return to a
    module already left), and the same walk from the live calibrator goes through the same session":

    every call between two dtscal_lib modules is traced (``sys.settrace``, every thread) while a bag is
    calibrated into a calibrations folder, once by the pipeline (the command line's driver) and once
    by the live calibrator (frames stepped, CALIBRATE, COMMIT to the folder). Modules are in three
    layers: drivers (cli, pipeline, ui), the session, and the areas below it -- detect (detect,
    coverage, boards), calibration (calibration, camera, the live tool's calibration process), judge
    (plausibility, quality, ground, report), files (calib_files, safe_yaml), robot. Then

    1. no call climbs: nothing below the session calls the session or a driver, the session calls no
       driver;
    2. the session enters each area once, in the order of the walk: detect (every frame offered, one
       after the other, is one visit) -> calibration -> judge -> files, never returning to an area it
       left;
    3. the steps themselves (detect_board, calibrate, intrinsic_doubts, save_intrinsics) are called
       by the session only, from both drivers: the live calibrator walks the same session.

    The walk that ends on the robot (COMMIT over ROS) is
    :func:`test_the_walk_to_the_robot_over_ros_goes_through_the_session`.
    """
    with Walk() as cli_walk:
        run = pipeline.calibrate_intrinsics(short_bag, out_dir=tmp_path / "cli")
    assert run.path == tmp_path / "cli" / "camera_intrinsic" / "walkbot.yaml" and run.path.exists()

    live_walk, msg = walk_the_live_calibrator(short_bag, tmp_path / "live", "folder")
    assert msg.startswith("COMMIT: wrote"), msg

    for walk in (cli_walk, live_walk):
        check_walk(walk, ["detect", "calibration", "judge", "files"], FOLDER_STEPS)


@pytest.mark.slow
def test_the_walk_to_the_robot_over_ros_goes_through_the_session(short_bag, tmp_path, monkeypatch, capsys):
    """The same walk to the end of the kit's real ROS path: a private ``roscore`` and a Duckiebot camera node
    (rospy, Debian's ROS 1) whose ``set_camera_info`` writes the robot-side ``camera_intrinsic/walkbot.yaml``.

    Traced as above: ``dtscal calibrate-intrinsics --commit`` (the command line, in this process) and the
    live calibrator's COMMIT with the target "robot over ROS". In both the session enters detect ->
    calibration -> judge -> files -> robot, each once and in that order, nothing climbs back, and
    ``commit_intrinsics`` (the send to the robot) is called by the session only. The robot-side file is the
    local one, number for number.
    """
    from ci import missing as missing_in_ci
    from ros_env import CAMERA_NODE, SYSTEM_PYTHON, _log, _missing_ros, _started, _wait, running_roscore

    from dtscal_lib import cli

    if _missing_ros():
        missing_in_ci(f"ROS 1 tools missing ({_missing_ros()}); install them with scripts/install-ros.sh")
    robot_root = tmp_path / "robot" / "data" / "config" / "calibrations"
    robot_side = robot_root / "camera_intrinsic" / "walkbot.yaml"
    script = tmp_path / "camera_node.py"
    script.write_text(CAMERA_NODE)
    node_log = tmp_path / "camera_node.log"
    with running_roscore(tmp_path / "home") as env, \
            _started([SYSTEM_PYTHON, str(script), "walkbot", str(robot_root)], env, node_log) as node:
        _wait(lambda: "READY" in _log(node_log) or node.poll() is not None, 60, "the camera node")
        assert node.poll() is None, _log(node_log)
        monkeypatch.setenv("ROS_MASTER_URI", env["ROS_MASTER_URI"])  # the live COMMIT's master (a bag has none)

        with Walk() as cli_walk:
            code = cli.main(["calibrate-intrinsics", "--source", str(short_bag), "--out", str(tmp_path / "cli"),
                             "--commit", "--master-uri", env["ROS_MASTER_URI"], "-q"])
        out = capsys.readouterr()
        assert code == 0, out.err
        local = tmp_path / "cli" / "camera_intrinsic" / "walkbot.yaml"
        assert f"committed to walkbot: Write to {robot_side}" in out.out, out
        np.testing.assert_allclose(calib_files.load_intrinsics(robot_side).K, calib_files.load_intrinsics(local).K,
                                   rtol=1e-12)
        robot_side.unlink()

        live_walk, msg = walk_the_live_calibrator(short_bag, tmp_path / "live", "ros")
        local = tmp_path / "live" / "camera_intrinsic" / "walkbot.yaml"
        assert msg == f"COMMIT to walkbot: Write to {robot_side} (local copy: {local})", msg
        np.testing.assert_allclose(calib_files.load_intrinsics(robot_side).K, calib_files.load_intrinsics(local).K,
                                   rtol=1e-12)

    for walk in (cli_walk, live_walk):
        check_walk(walk, ["detect", "calibration", "judge", "files", "robot"], ROBOT_STEPS)


def test_the_cli_writes_nothing_when_the_verdict_step_fails(short_bag, tmp_path, monkeypatch, capsys):
    """The verdict is a step of the session, computed before anything is written: when it fails (here the
    judge raises), ``dtscal calibrate-intrinsics`` prints the camera, says why there is no verdict, exits 3
    (refused) and writes no file; ``--keep-anyway`` keeps it only as ``ROBOT.rejected.yaml`` beside."""
    from dtscal_lib import cli, quality

    def broken_judge(result, evidence, **kw):
        raise RuntimeError("the judge broke")

    monkeypatch.setattr(quality, "assess", broken_judge)
    out = tmp_path / "calibrations"
    code = cli.main(["calibrate-intrinsics", "--source", str(short_bag), "--out", str(out), "-q"])
    err = capsys.readouterr().err
    assert code == REFUSED, err
    assert "could not judge this calibration" in err and "the judge broke" in err
    assert files_under(out) == []
    code = cli.main(["calibrate-intrinsics", "--source", str(short_bag), "--out", str(out), "-q", "--keep-anyway"])
    assert code == REFUSED
    assert files_under(out) == ["camera_intrinsic/walkbot.rejected.yaml"]
