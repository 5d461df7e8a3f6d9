"""The live calibrator's frame loop: speed, CALIBRATE while frames flow, memory over a long session.

Part 1, the frame loop at 640x480: for every frame, decode the JPEG, detect the board, offer it to
the coverage bars, draw the corners, encode the JPEG the widget sends (the calibrator's own
``FrameLoop.step``, widget updates included). Two inputs: the bundled recording, and board-free
cluttered frames (``common.clutter_image``, the classic detector's slow case). Baseline, measured on
the same frames in the same run: a ROS-style loop, i.e. the same steps with ROS's full-frame
``findChessboardCorners(ADAPTIVE_THRESH | NORMALIZE_IMAGE | FAST_CHECK)`` as the detector.
Target: median >= 30 fps in both cases.

Part 2, CALIBRATE with 40 samples while the recording plays at 30 fps into the live loop: its time
(target < 1 s; baseline: ``cv2.calibrateCamera`` on the same samples in a thread of the process that
shows the frames, as ROS's calibrator runs it, with its own longest gap) and the longest gap between
two displayed frames while it runs (target < 100 ms; the camera's own period
is 33 ms), from the press until 0.5 s after the verdict is shown. Two sample sets: the first 40 of
the recording, and 40 spread over all of it (one outlier view: two fits). Also printed: the CPU the
solver process used, the longest single loop step in the window with its own CPU time (a frame the
detector works long on makes a gap by itself, CALIBRATE or not), and the longest gap over an equally
long window right after, without CALIBRATE (what the loop does on this machine at this moment).

Part 3, memory: the recording looped as fast as it decodes until the source has delivered 18,000
frames (ten minutes of camera at 30 fps) through the live loop; RSS at the start and at the end.

Part 4, the robot's link: the recording published at 30 fps by a robot over DTPS (dtps-http's own server,
Duckietown's topic and message types: ``tests/dtps_robot.py``) and over ROS 1 (a private ``roscore``, ROS's
``rosbag play --loop`` on the Duckiebot's topic, the kit's rospy helper), one after the other in one run,
into the live calibrator (``LiveCalibrator("dtps:ROBOT@...")`` / ``LiveCalibrator("ros:ROBOT")``): frames
received and shown per second over 10 s, then CALIBRATE on the samples collected (its time).

Usage::

    .venv/bin/python benchmarks/bench_live.py            # full (a few minutes)
    .venv/bin/python benchmarks/bench_live.py --quick    # fewer frames, 3,000 for the memory part
    .venv/bin/python benchmarks/bench_live.py --parts 2 --runs 5   # CALIBRATE only, five times, with ranges
    .venv/bin/python benchmarks/bench_live.py --parts 4            # DTPS beside ROS 1
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import threading
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common import FrameRenderer, clutter_image  # noqa: E402

from dtscal_lib import datasets  # noqa: E402
from dtscal_lib.coverage import CoverageTracker  # noqa: E402
from dtscal_lib.detect import detect_board_ros, draw_detection  # noqa: E402
from dtscal_lib.sources import decode_image  # noqa: E402
from dtscal_lib.sources.frame import Frame  # noqa: E402
from dtscal_lib.ui import LiveCalibrator  # noqa: E402
from dtscal_lib.ui.render import encode_jpeg  # noqa: E402

BAG = datasets.session_dir() / "intrinsics.bag"
TARGET_FPS, TARGET_CALIBRATE_S, TARGET_GAP_S = 30.0, 1.0, 0.1


def rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def recording_jpegs(step: int = 1) -> list[bytes]:
    return [data for i, (_, _, data) in enumerate(datasets.read_bag_jpegs(BAG)) if i % step == 0]


def clutter_jpegs(n: int, seed: int = 5) -> list[bytes]:
    rng = np.random.default_rng(seed)
    renderer = FrameRenderer()
    kinds = ("rects", "tiles", "office", "mixed")
    return [encode_jpeg(renderer.render_empty(clutter_image(rng, kind=kinds[k % len(kinds)]), rng).image, 85)
            for k in range(n)]


def dtscal_loop(jpegs: list[bytes]) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame wall and CPU seconds of the calibrator's loop body (decode + FrameLoop.step)."""
    app = LiveCalibrator(str(BAG), autostart=False)
    wall, cpu = [], []
    for i, data in enumerate(jpegs):
        t0, c0 = time.perf_counter(), time.process_time()
        img = decode_image(data)
        app.loop.step(Frame(i, i / 30.0, img, None, f"#{i}"))
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    assert not app.loop.errors, app.loop.last_error
    app.close()
    return np.array(wall), np.array(cpu)


def ros_loop(jpegs: list[bytes]) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame wall and CPU seconds of the same steps with ROS's full-frame detector."""
    tracker = CoverageTracker()
    wall, cpu = [], []
    for i, data in enumerate(jpegs):
        t0, c0 = time.perf_counter(), time.process_time()
        img = decode_image(data)
        det = detect_board_ros(img)
        if det.found:
            tracker.offer(det, i)
        encode_jpeg(draw_detection(img, det))
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return np.array(wall), np.array(cpu)


def part_loop(quick: bool) -> list[tuple]:
    rows = []
    for name, jpegs in (("recording (board in most frames)", recording_jpegs(2 if quick else 1)),
                        ("board-free cluttered frames", clutter_jpegs(12 if quick else 30))):
        (ours, ours_cpu), (ros, ros_cpu) = dtscal_loop(jpegs), ros_loop(jpegs)
        fps, ros_fps = 1.0 / np.median(ours), 1.0 / np.median(ros)
        rows.append((name, len(jpegs), fps, ros_fps, np.percentile(ours, 95) * 1e3, 1.0 / np.median(ours_cpu),
                     1.0 / np.median(ros_cpu)))
    return rows


def process_cpu_s(pid: int) -> float:
    """User + system CPU seconds a process has used so far (Linux ``/proc``; NaN elsewhere)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return float("nan")


def wait_for(cond, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while not cond() and time.monotonic() < end:
        time.sleep(0.01)
    return cond()


class StepClock:
    """Wraps a tool's ``on_frame``: when each loop step ran and the CPU time its thread spent on it.

    Only reads clocks around the real step (a few microseconds); it tells a gap caused by the step
    itself (a frame the detector works long on) from a gap caused by something else (the CPU or
    the interpreter taken by CALIBRATE).
    """

    def __init__(self, on_frame):
        self.on_frame, self.steps = on_frame, []

    def __call__(self, frame):
        t0, c0 = time.perf_counter(), time.thread_time()
        try:
            return self.on_frame(frame)
        finally:
            self.steps.append((t0, time.perf_counter(), time.thread_time() - c0, frame.index))

    def longest(self, since: float, until: float = float("inf")) -> tuple[float, float, int]:
        """(wall s, own CPU s, frame index) of the longest step that started in [since, until)."""
        inside = [s for s in self.steps if since <= s[0] < until]
        if not inside:
            return 0.0, 0.0, -1
        t0, t1, cpu, index = max(inside, key=lambda s: s[1] - s[0])
        return t1 - t0, cpu, index


def part_calibrate(which: str) -> dict:
    """CALIBRATE on 40 samples while the recording plays live (30 fps, looped) into the same calibrator.

    ``which="first"``: the first 40 samples of the recording; ``"spread"``: 40 samples spread over
    the whole recording (one of them is an outlier view: the solver calibrates again without it).
    The gap is measured from the press until 0.5 s after the verdict is shown (the whole CALIBRATE
    job, the quality assessment included); then, as a reference, the same loop over an equally long
    window without CALIBRATE.
    """
    app = LiveCalibrator(str(BAG), realtime=True, loop=True, autostart=False)
    from dtscal_lib.sources import open_source

    for f in open_source(BAG):
        if f.ok:
            app.loop.step(f)
        if which == "first" and app.tracker is not None and len(app.tracker.samples) >= 40:
            break
    samples = app.tracker.samples
    keep = np.linspace(0, len(samples) - 1, 40).round().astype(int) if which == "spread" else range(40)
    app.tracker.samples = [samples[i] for i in keep]
    obj, img = app.tracker.object_and_image_points()
    app.prepare_calibration(wait=120)  # done by itself at the third sample, long before CALIBRATE
    clock = app.loop.on_frame = StepClock(app.loop.on_frame)
    app.loop.start()
    wait_for(lambda: app.loop.shown > 60, 30)
    # baseline, ROS's way: cv2.calibrateCamera in a thread of the process that shows the frames
    t0 = time.perf_counter()
    job = threading.Thread(target=cv2.calibrateCamera, args=(
        [o.astype(np.float32) for o in obj], [i.astype(np.float32) for i in img], (640, 480), None, None))
    job.start()
    job.join()
    baseline = time.perf_counter() - t0
    time.sleep(0.5)
    baseline_gap = app.loop.longest_gap(t0)
    shown0 = app.loop.shown
    solver_pid = app._solver._proc.pid if app._solver is not None else -1
    cpu0 = process_cpu_s(solver_pid)
    t0 = time.perf_counter()
    app.calibrate(wait=True)
    solver_cpu = process_cpu_s(solver_pid) - cpu0  # calibration and verdict, in the solver's process
    assert app.result is not None, app.calibrate_error
    during = app.loop.shown - shown0
    time.sleep(0.5)  # the first frame after CALIBRATE closes the last gap
    t1 = time.perf_counter()
    gap = app.loop.longest_gap(t0)
    step = clock.longest(t0, t1)
    time.sleep(t1 - t0)  # reference: the same loop, as long again, without CALIBRATE
    times = [x for x in list(app.loop.display_times) if x >= t1]
    ref_gap = max((b - a for a, b in zip(times, times[1:])), default=0.0)
    ref_step = clock.longest(t1)
    app.close()
    return {"seconds": app.calibrate_seconds, "baseline": baseline, "gap": gap, "frames_during": during,
            "baseline_gap": baseline_gap, "window": t1 - t0, "step": step, "ref_gap": ref_gap,
            "ref_step": ref_step, "solver_cpu": solver_cpu, "views": app.result.n_views, "dropped": len(app.dropped),
            "which": which}


def part_memory(n_frames: int) -> dict:
    app = LiveCalibrator(str(BAG), realtime=False, loop=True)
    wait_for(lambda: app.source.status.frames >= 500, 300)
    start, received0, t0 = rss_mb(), app.source.status.frames, time.perf_counter()
    peak = start
    while app.source.status.frames < n_frames:
        time.sleep(0.5)
        peak = max(peak, rss_mb())
    end = rss_mb()
    out = {"start": start, "end": end, "peak": peak, "received": app.source.status.frames - received0,
           "shown": app.loop.shown, "samples": len(app.samples), "seconds": time.perf_counter() - t0}
    app.close()
    return out


@contextlib.contextmanager
def dtps_robot():
    """The recording on a robot's DTPS switchboard (dtps-http's server); yields the source spec."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from dtps_robot import DtpsRobotServer

    with DtpsRobotServer(fps=30.0) as robot:
        yield robot.spec


@contextlib.contextmanager
def ros1_robot(tmp: Path):
    """The recording played onto a Duckiebot's topic by ``rosbag play --loop`` on a private roscore."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from ros_env import ROBOT, _ros_tool, _started, running_roscore

    with running_roscore(tmp) as env:
        os.environ.update({k: env[k] for k in ("ROS_MASTER_URI", "ROS_HOSTNAME") if k in env})
        with _started([_ros_tool("rosbag"), "play", "--quiet", "--loop", str(BAG)], env, tmp / "play.log"):
            yield f"ros:{ROBOT}"


def part_sources(seconds: float = 10.0) -> list[dict]:
    """Frames received and shown per second from each robot link, then CALIBRATE's time on what was collected."""
    import tempfile

    rows = []
    with tempfile.TemporaryDirectory(prefix="dtscal-bench-live-") as tmp:
        for name, robot in (("DTPS (dtps-http switchboard, duckietown-messages)", dtps_robot()),
                            ("ROS 1 (roscore, rosbag play, rospy helper)", ros1_robot(Path(tmp)))):
            with robot as spec:
                app = LiveCalibrator(spec, calibration_dir=tmp)
                wait_for(lambda app=app: app.source.status.state == "running", 60)
                received0, shown0, t0 = app.source.status.frames, app.loop.shown, time.perf_counter()
                time.sleep(seconds)
                dt_s = time.perf_counter() - t0
                received, shown = app.source.status.frames - received0, app.loop.shown - shown0
                wait_for(lambda app=app: not app.calibrate_button.disabled, 120)
                app.calibrate(wait=True)
                rows.append({"name": name, "received_fps": received / dt_s, "shown_fps": shown / dt_s,
                             "samples": len(app.samples), "calibrate_s": app.calibrate_seconds,
                             "ok": app.result is not None})
                app.close()
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer frames (memory part: 3,000)")
    ap.add_argument("--parts", default="1,2,3", help="which parts to run, e.g. 2 (default 1,2,3)")
    ap.add_argument("--runs", type=int, default=1, help="repeat part 2 this many times (default 1)")
    args = ap.parse_args(argv)
    parts = {p.strip() for p in args.parts.split(",")}
    ok = True
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at the start")
    if "1" in parts:
        print("Part 1: live frame loop, 640x480 (decode, detect, coverage, draw, JPEG for the widget)")
        print(f"  {'input':36s} {'frames':>6s} {'dtscal fps':>11s} {'ROS-style fps':>14s} {'ratio':>7s} {'p95 ms':>7s}"
              f"  {'CPU-time fps: dtscal / ROS-style':>33s}")
        for name, n, fps, ros_fps, p95, cpu_fps, ros_cpu_fps in part_loop(args.quick):
            print(f"  {name:36s} {n:6d} {fps:11.1f} {ros_fps:14.1f} {fps / ros_fps:6.1f}x {p95:7.1f}"
                  f"  {cpu_fps:24.1f} / {ros_cpu_fps:.1f}")
            ok &= fps >= TARGET_FPS
        print(f"  target: median >= {TARGET_FPS:g} fps in both (wall time; CPU-time fps is what one free core gives)")
    if "2" in parts:
        print("Part 2: CALIBRATE with 40 samples while the recording plays at 30 fps into the loop")
        runs: dict[str, list] = {"first": [], "spread": []}
        for _ in range(max(1, args.runs)):
            for which in ("first", "spread"):
                c = part_calibrate(which)
                runs[which].append(c)
                label = "first 40 samples" if which == "first" else "40 samples spread over the recording"
                print(f"  {label}: {c['seconds'] * 1e3:.0f} ms ({c['dropped']} outlier view(s) dropped; the solver "
                      f"process used {c['solver_cpu'] * 1e3:.0f} ms of CPU for the calibration and the verdict); "
                      f"ROS-style cv2.calibrateCamera in a thread on the same samples {c['baseline'] * 1e3:.0f} ms, "
                      f"ratio {c['seconds'] / c['baseline']:.2f}x; target < {TARGET_CALIBRATE_S:g} s")
                print(f"    frames displayed meanwhile: {c['frames_during']}; longest gap between displayed frames "
                      f"{c['gap'] * 1e3:.0f} ms (ROS-style: {c['baseline_gap'] * 1e3:.0f} ms); "
                      f"target < {TARGET_GAP_S * 1e3:.0f} ms")
                (sw, sc, si), (rw, rc, ri) = c["step"], c["ref_step"]
                print(f"    longest loop step in that {c['window']:.1f} s: {sw * 1e3:.0f} ms (frame #{si}, "
                      f"{sc * 1e3:.0f} ms of its own CPU); the next {c['window']:.1f} s without CALIBRATE: longest "
                      f"gap {c['ref_gap'] * 1e3:.0f} ms, longest step {rw * 1e3:.0f} ms (frame #{ri}, "
                      f"{rc * 1e3:.0f} ms CPU); load average {os.getloadavg()[0]:.1f}")
                ok &= c["seconds"] < TARGET_CALIBRATE_S and c["gap"] < TARGET_GAP_S
        if args.runs > 1:
            for which, cs in runs.items():
                def rng(key, cs=cs):
                    v = [1e3 * c[key] for c in cs]
                    return f"{min(v):.0f}-{max(v):.0f} (median {np.median(v):.0f})"
                print(f"  {which}, {len(cs)} runs: CALIBRATE {rng('seconds')} ms, cv2 {rng('baseline')} ms; "
                      f"longest gap {rng('gap')} ms, ROS-style {rng('baseline_gap')} ms, "
                      f"without CALIBRATE {rng('ref_gap')} ms")
    if "4" in parts:
        print("Part 4: the robot's link, the recording published at 30 fps, 10 s into the live calibrator")
        rows = part_sources()
        for r in rows:
            print(f"  {r['name']:52s} received {r['received_fps']:5.1f} fps, shown {r['shown_fps']:5.1f} fps; "
                  f"CALIBRATE on {r['samples']} samples {r['calibrate_s'] * 1e3:.0f} ms")
            ok &= r["ok"]
        if len(rows) == 2 and rows[1]["shown_fps"] > 0:
            print(f"  DTPS / ROS 1: shown fps ratio {rows[0]['shown_fps'] / rows[1]['shown_fps']:.2f}, CALIBRATE "
                  f"time ratio {rows[0]['calibrate_s'] / rows[1]['calibrate_s']:.2f}")
    if "3" in parts:
        n = 3000 if args.quick else 18000
        m = part_memory(n)
        print(f"Part 3: memory over {m['received']} frames played as fast as possible ({m['seconds']:.0f} s, "
              f"{m['shown']} displayed, {m['samples']} samples kept)")
        print(f"  RSS start {m['start']:.1f} MB, end {m['end']:.1f} MB, peak {m['peak']:.1f} MB "
              f"(growth {m['end'] - m['start']:+.1f} MB)")
        ok &= m["end"] - m["start"] < 50
    print(f"load average at the end {os.getloadavg()[0]:.1f}")
    print("all targets met" if ok else "SOME TARGETS MISSED (see above; the machine may be loaded)")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
