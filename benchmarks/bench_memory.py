"""Benchmark: memory and time of intrinsic calibration against the number of views.

Each case runs in a fresh Python process, so one case's heap cannot hide another's:
the process builds V views of the 7x5 Duckietown board (35 corners, the realistic noisy
views of ``bench_calibrate.py``, repeated with fresh noise), notes its resident memory
(the baseline), resets the kernel's peak-RSS counter (``/proc/self/clear_refs``) and runs
``dtscal_lib.calibration.calibrate``. Reported: peak resident memory above that baseline
and wall time, each also as a ratio to the 100-view case of the same run. Linear growth
shows as ratios close to V / 100; the acceptance target is 4000 views under 300 MB.

**Through the command line** (``--cli``), as a user runs it: V still images of the board in a folder
(``N_DISTINCT`` synthetic renderings through the Duckiebot camera, each hard-linked V / N_DISTINCT
times; a folder of stills uses every view in which the board is found), then
``dtscal calibrate-intrinsics --source FOLDER --no-write --json -q`` run by ``dtscal_lib.cli.main`` in
a fresh process. Reported: the peak resident memory of the whole command above its baseline (after
the imports), and the verdict step (``quality.assess``: verdict, corner noise, systematic-residual
checks, uncertainty map, consequences) on its own: its peak above the memory when it started, and
its time. The acceptance target: 4000 views under 300 MB extra and the verdict under 10 s.

Run::

    .venv/bin/python benchmarks/bench_memory.py [--views 100 1000 4000] [--json] [--check]
    .venv/bin/python benchmarks/bench_memory.py --cli [--views 100 1000 4000] [--check]
    .venv/bin/python benchmarks/bench_memory.py --cli --quick     # 100 and 1000 views

Linux only (it reads ``/proc/self/status``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
TARGET_MB = 300.0
TARGET_VIEWS = 4000
#: the verdict step's time target at TARGET_VIEWS views, seconds
TARGET_QUALITY_S = 10.0
#: distinct rendered views behind the CLI case's folder
N_DISTINCT = 40

_CHILD = r"""
import json, sys, time
sys.path.insert(0, {here!r}); sys.path.insert(0, {root!r})
import numpy as np
from bench_calibrate import make_views
from dtscal_lib import duckietown as dt
from dtscal_lib.calibration import calibrate

def status(key):
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1]) / 1024.0
    raise SystemExit("no " + key + " in /proc/self/status")

n = {n}
objs, imgs = make_views(seed=1, n=40)
rng = np.random.default_rng(2)
objs = [objs[k % 40] for k in range(n)]
imgs = [imgs[k % 40] + rng.normal(0.0, 0.05, imgs[k % 40].shape) for k in range(n)]
calibrate(objs[:40], imgs[:40], dt.IMAGE_SIZE)  # warm up imports and caches outside the measurement
base = status("VmRSS")
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")  # reset VmHWM (the peak) to the current RSS
t0 = time.perf_counter()
res = calibrate(objs, imgs, dt.IMAGE_SIZE)
dt_s = time.perf_counter() - t0
print(json.dumps({{"views": n, "points": int(res.n_points), "peak_above_baseline_mb": status("VmHWM") - base,
                  "seconds": dt_s, "iterations": res.iterations, "fx": float(res.K[0, 0])}}))
"""


_CLI_CHILD = r"""
import json, sys, time
sys.path.insert(0, {root!r})
from dtscal_lib import calibration, cli, quality

def status(key):
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1]) / 1024.0
    raise SystemExit("no " + key + " in /proc/self/status")

seen = {{}}
inner = quality.assess

def measured_assess(result, evidence, **kw):  # the verdict step of the command, measured on its own
    start = status("VmRSS")
    peak_before = status("VmHWM")
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")
    t0 = time.perf_counter()
    q = inner(result, evidence, **kw)
    seen.update(quality_seconds=time.perf_counter() - t0, quality_peak_above_start_mb=status("VmHWM") - start,
                views=int(result.n_views), points=int(result.n_points), verdict=q.verdict)
    seen["command_peak_mb"] = max(seen.get("command_peak_mb", 0.0), peak_before)
    return q

quality.assess = measured_assess
base = status("VmRSS")
t0 = time.perf_counter()
code = cli.main(["calibrate-intrinsics", "--source", {folder!r}, "--no-write", "--json", "-q"])
seen["command_seconds"] = time.perf_counter() - t0
seen["command_peak_above_baseline_mb"] = max(seen.get("command_peak_mb", 0.0), status("VmHWM")) - base
seen["exit_code"] = code
print(json.dumps(seen), file=sys.stderr)
"""


def make_folder(folder: Path, n: int) -> Path:
    """``n`` still images of the board in ``folder``: N_DISTINCT renderings, hard-linked round-robin."""
    import cv2
    import numpy as np

    sys.path.insert(0, str(HERE.parent))
    from common import random_visible_pose

    from dtscal_lib import synth
    from dtscal_lib.boards import DUCKIETOWN_BOARD

    src = folder / "distinct"
    src.mkdir(parents=True, exist_ok=True)
    cam = synth.synthetic_camera()
    renderer = synth.make_renderer(cam)
    rng = np.random.default_rng(5)
    distinct = []
    for k in range(min(n, N_DISTINCT)):
        rvec, tvec, _ = random_visible_pose(rng, DUCKIETOWN_BOARD, cam.K, cam.dist, distance=(0.3, 0.6), margin=30)
        img = synth.render_view(cam, DUCKIETOWN_BOARD, rvec, tvec, rng=rng, renderer=renderer)[0]
        path = src / f"view{k:02d}.png"
        cv2.imwrite(str(path), img)
        distinct.append(path)
    views = folder / f"views{n}"
    views.mkdir(exist_ok=True)
    for i in range(n):
        target = views / f"frame{i:05d}.png"
        if not target.exists():
            os.link(distinct[i % len(distinct)], target)
    return views


def measure_cli(n: int, workdir: Path) -> dict:
    folder = make_folder(workdir, n)
    code = _CLI_CHILD.format(root=str(HERE.parent), folder=str(folder))
    out = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True, timeout=3600)
    lines = [ln for ln in out.stderr.strip().splitlines() if ln.startswith("{")]
    if not lines:
        raise SystemExit(f"the {n}-view command failed:\n{out.stderr[-2000:]}")
    row = json.loads(lines[-1])
    if row.get("exit_code") not in (0, 3) or "quality_seconds" not in row:
        raise SystemExit(f"the {n}-view command did not reach its verdict: {row}\n{out.stderr[-2000:]}")
    row["folder_views"] = n
    return row


def main_cli(args) -> int:
    import tempfile

    with tempfile.TemporaryDirectory(prefix="dtscal-bench-memory-") as tmp:
        rows = [measure_cli(n, Path(tmp)) for n in args.views]
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        print("dtscal calibrate-intrinsics --source FOLDER --no-write --json -q, FOLDER = V still images "
              f"({N_DISTINCT} distinct renderings)")
        print(f"{'views':>6s} {'command peak':>13s} {'command time':>13s} {'verdict peak':>13s} "
              f"{'verdict time':>13s}  verdict")
        for r in rows:
            print(f"{r['views']:6d} {r['command_peak_above_baseline_mb']:10.1f} MB {r['command_seconds']:12.1f}s "
                  f"{r['quality_peak_above_start_mb']:10.1f} MB {r['quality_seconds']:12.2f}s  {r['verdict']}")
    big = [r for r in rows if r["views"] >= TARGET_VIEWS]
    ok = all(r["command_peak_above_baseline_mb"] < TARGET_MB and r["quality_seconds"] < TARGET_QUALITY_S for r in big)
    if big and not args.json:
        print(f"target: {TARGET_VIEWS} views < {TARGET_MB:g} MB above baseline and the verdict < "
              f"{TARGET_QUALITY_S:g} s: {'ok' if ok else 'MISSED'}")
    return 1 if args.check and not ok else 0


def measure(n: int) -> dict:
    code = _CHILD.format(here=str(HERE), root=str(HERE.parent), n=int(n))
    out = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True, timeout=1800)
    if out.returncode != 0:
        raise SystemExit(f"the {n}-view case failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--views", type=int, nargs="+", default=[100, 1000, 4000])
    ap.add_argument("--json", action="store_true", help="print the numbers as JSON")
    ap.add_argument("--check", action="store_true", help=f"exit 1 if {TARGET_VIEWS} views exceed {TARGET_MB:g} MB")
    ap.add_argument("--cli", action="store_true", help="measure the dtscal calibrate-intrinsics command on a folder "
                    "of V still images, and its verdict step")
    ap.add_argument("--quick", action="store_true", help="100 and 1000 views only")
    args = ap.parse_args(argv)
    if args.quick:
        args.views = [100, 1000]
    if args.cli:
        return main_cli(args)
    rows = [measure(n) for n in args.views]
    base = rows[0]
    for r in rows:
        r["memory_ratio"] = r["peak_above_baseline_mb"] / max(base["peak_above_baseline_mb"], 1e-9)
        r["time_ratio"] = r["seconds"] / base["seconds"]
        r["per_view_ms"] = 1e3 * r["seconds"] / r["views"]
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        print(f"calibrate() on V views of 35 corners; baseline: the {base['views']}-view case of this run")
        print(f"{'views':>6s} {'peak above base':>16s} {'x base':>7s} {'time':>9s} {'x base':>7s} "
              f"{'ms/view':>8s} {'iters':>6s}")
        for r in rows:
            print(f"{r['views']:6d} {r['peak_above_baseline_mb']:13.1f} MB {r['memory_ratio']:7.1f} "
                  f"{r['seconds']:8.2f}s {r['time_ratio']:7.1f} {r['per_view_ms']:8.2f} {r['iterations']:6d}")
    big = [r for r in rows if r["views"] >= TARGET_VIEWS]
    ok = all(r["peak_above_baseline_mb"] < TARGET_MB for r in big)
    if big and not args.json:
        print(f"target: {TARGET_VIEWS} views < {TARGET_MB:g} MB above baseline: {'ok' if ok else 'MISSED'}")
    return 1 if args.check and not ok else 0


if __name__ == "__main__":
    sys.exit(main())
