"""Benchmark: the hand-out's first ``bash start.sh``, from scratch, with uv beside plain pip.

Issue 23's target: the first start (no ``.venv``; the package caches warm) under 30 s on 2 quiet cores,
and never silent for more than 10 s. What a student runs is measured: the hand-out written by
``dtscal handout``, copied to a fresh folder, ``bash start.sh --setup-only`` (everything up to the point
where JupyterLab would start: the environment, the install, the workspace). The baseline, in the same run
on the same hand-out: ``DTSCAL_INSTALLER=pip bash start.sh --setup-only``, the same script installing
with pip alone (upgrading pip, then ``pip install -e .``: what start.sh did before uv).

Each run's output (stdout and stderr, as the student's terminal shows them) is read chunk by chunk with
its arrival time: the longest silent stretch is the longest gap between two chunks (from the start to
the first, and from the last to the exit, included). Each start.sh phase line (``[1/3]`` ...) is timed.
A warm-up run of each installer first fills its cache (``--no-warmup`` skips it when the caches are known
to be warm). The load average is printed: the target is for a quiet machine.

Run::

    .venv/bin/python benchmarks/bench_start.py [--runs 1] [--no-warmup] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import select
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def make_handout(where: Path) -> Path:
    out = where / "handout"
    subprocess.run([sys.executable, "-m", "dtscal_lib.cli", "handout", str(out)], cwd=ROOT, check=True,
                   stdout=subprocess.DEVNULL)
    return out


def run_start(handout: Path, where: Path, installer: str) -> dict:
    """``bash start.sh --setup-only`` in a fresh copy of ``handout``; times and silences."""
    folder = where / f"course-{installer}-{time.monotonic_ns()}"
    shutil.copytree(handout, folder, symlinks=True)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("VIRTUAL_ENV", "PYTHONPATH", "DTSCAL_"))}
    env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep) if ".venv" not in p)
    env["DTSCAL_INSTALLER"] = installer
    t0 = time.monotonic()
    proc = subprocess.Popen(["bash", "start.sh", "--setup-only"], cwd=folder, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    fd = proc.stdout.fileno()
    arrivals, text = [0.0], bytearray()
    phases = {}
    while True:
        ready, _, _ = select.select([fd], [], [], 1.0)
        if not ready:
            continue
        chunk = os.read(fd, 65536)
        if not chunk:
            break
        now = time.monotonic() - t0
        arrivals.append(now)
        before = len(text)
        text += chunk
        for line in bytes(text[max(0, before - 200):]).decode(errors="replace").splitlines():
            if line.startswith("start.sh: [") and line[11:14] not in phases:
                phases[line[11:14]] = now
    code = proc.wait()
    total = time.monotonic() - t0
    arrivals.append(total)
    gaps = [b - a for a, b in zip(arrivals, arrivals[1:])]
    longest = max(gaps)
    at = arrivals[gaps.index(longest)]
    shutil.rmtree(folder, ignore_errors=True)
    if code != 0:
        tail = text.decode(errors="replace")[-3000:]
        raise SystemExit(f"start.sh ({installer}) failed with exit code {code}:\n{tail}")
    return {"installer": installer, "seconds": round(total, 2), "longest_silence_s": round(longest, 2),
            "silence_starts_at_s": round(at, 2), "phases_s": {k: round(v, 2) for k, v in sorted(phases.items())}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1, help="measured runs of each installer (after the warm-up)")
    ap.add_argument("--no-warmup", action="store_true", help="measure the first runs (caches known warm)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    load = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="bench-start-") as tmp:
        where = Path(tmp)
        handout = make_handout(where)
        if not args.no_warmup:
            for installer in ("uv", "pip"):
                print(f"warm-up ({installer}) ...", file=sys.stderr, flush=True)
                run_start(handout, where, installer)
        results = []
        for _ in range(args.runs):
            for installer in ("uv", "pip"):
                results.append(run_start(handout, where, installer))
                print(json.dumps(results[-1]), file=sys.stderr, flush=True)
    best = {i: min((r for r in results if r["installer"] == i), key=lambda r: r["seconds"]) for i in ("uv", "pip")}
    summary = {"load_at_start": [round(x, 2) for x in load], "cores": os.cpu_count(), "runs": results,
               "uv_s": best["uv"]["seconds"], "pip_s": best["pip"]["seconds"],
               "ratio_uv_over_pip": round(best["uv"]["seconds"] / best["pip"]["seconds"], 3),
               "uv_longest_silence_s": max(r["longest_silence_s"] for r in results if r["installer"] == "uv"),
               "pip_longest_silence_s": max(r["longest_silence_s"] for r in results if r["installer"] == "pip")}
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(f"load average at start {summary['load_at_start']} on {summary['cores']} cores")
        for r in results:
            print(f"  {r['installer']:>3}: {r['seconds']:6.1f} s, longest silence {r['longest_silence_s']:.1f} s "
                  f"(from {r['silence_starts_at_s']:.1f} s), phases {r['phases_s']}")
        print(f"first start.sh --setup-only: uv {summary['uv_s']:.1f} s, pip {summary['pip_s']:.1f} s "
              f"(uv/pip {summary['ratio_uv_over_pip']:.2f}); longest silence uv {summary['uv_longest_silence_s']:.1f}"
              f" s, pip {summary['pip_longest_silence_s']:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
