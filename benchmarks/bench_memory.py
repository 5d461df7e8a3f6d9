"""Benchmark: memory and time of intrinsic calibration against the number of views.

Each case runs in a fresh Python process, so one case's heap cannot hide another's:
the process builds V views of the 7x5 Duckietown board (35 corners, the realistic noisy
views of ``bench_calibrate.py``, repeated with fresh noise), notes its resident memory
(the baseline), resets the kernel's peak-RSS counter (``/proc/self/clear_refs``) and runs
``dtscal_lib.calibration.calibrate``. Reported: peak resident memory above that baseline
and wall time, each also as a ratio to the 100-view case of the same run. Linear growth
shows as ratios close to V / 100; the acceptance target is 4000 views under 300 MB.

Run::

    .venv/bin/python benchmarks/bench_memory.py [--views 100 1000 4000] [--json] [--check]

Linux only (it reads ``/proc/self/status``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
TARGET_MB = 300.0
TARGET_VIEWS = 4000

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
    args = ap.parse_args(argv)
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
