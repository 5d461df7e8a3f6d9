"""Benchmark: the first start from scratch, as a student (`bash start.sh`) and in a checkout (`scripts/course.sh`).

Issue 23's target: the hand-out's first start (no ``.venv``; the package caches warm) under 30 s on 2 quiet cores,
and never silent for more than 10 s. Issue 32: the checkout's ``scripts/course.sh`` (the README's first command)
shares start.sh's installer (``scripts/install-course.sh``: uv, progress lines), and neither goes quiet while
JupyterLab starts (``dtscal course`` says so every 5 s until JupyterLab serves).

What a student and an instructor run is measured, in one run, up to the moment JupyterLab serves (the first line
naming its address):

* ``start.sh``: the hand-out written by ``dtscal handout``, copied to a fresh folder,
  ``bash start.sh --no-browser --port P --ip 127.0.0.1``;
* ``course.sh``: a fresh copy of the checkout (its tracked files, no ``.venv``),
  ``bash scripts/course.sh --no-browser --port P --ip 127.0.0.1``;
* with ``--pip``, the baseline: start.sh with ``DTSCAL_INSTALLER=pip`` (pip upgraded, then ``pip install -e .``:
  what start.sh did before uv, and course.sh before issue 32).

Each run's output (stdout and stderr, as the terminal shows them) is read chunk by chunk with its arrival time: the
longest silent stretch is the longest gap between two chunks (from the start to the first, up to the address
line), with where it began and the line before it. Each phase line (``[1/3]`` ...) is timed. A warm-up run of each
installer first fills its cache (``--no-warmup`` skips it when the caches are known to be warm). The load average is
printed at the start and the end; ``--load N`` runs N busy processes (bounded: they stop with the benchmark, and
by themselves after 20 minutes) to measure "at load" on purpose.

Run::

    .venv/bin/python benchmarks/bench_start.py [--load 8] [--pip] [--no-warmup] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import select
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BUSY = "import time\nt = time.monotonic()\nwhile time.monotonic() - t < 1200:\n    pass\n"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def make_handout(where: Path) -> Path:
    out = where / "handout"
    subprocess.run([sys.executable, "-m", "dtscal_lib.cli", "handout", str(out)], cwd=ROOT, check=True,
                   stdout=subprocess.DEVNULL)
    return out


def make_checkout(where: Path) -> Path:
    """The checkout's tracked files (as a fresh clone has them, with this working tree's changes), no .venv."""
    out = where / "checkout"
    files = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout.split(b"\0")
    for rel in filter(None, (f.decode() for f in files)):
        if (ROOT / rel).is_file():
            (out / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / rel, out / rel)
    return out


def run_start(source: Path, where: Path, what: str, installer: str = "uv") -> dict:
    """The first start of ``what`` (``start.sh`` or ``course.sh``) in a fresh copy of ``source``, until JupyterLab
    serves; times and silences."""
    folder = where / f"{what}-{installer}-{time.monotonic_ns()}"
    shutil.copytree(source, folder, symlinks=True)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("VIRTUAL_ENV", "PYTHONPATH", "DTSCAL_"))}
    env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep) if ".venv" not in p)
    env.update(DTSCAL_INSTALLER=installer, JUPYTER_RUNTIME_DIR=str(folder / ".rt"),
               JUPYTER_CONFIG_DIR=str(folder / ".cfg"), JUPYTER_DATA_DIR=str(folder / ".jdata"))
    port = _free_port()
    script = "start.sh" if what == "start.sh" else "scripts/course.sh"
    t0 = time.monotonic()
    proc = subprocess.Popen(["bash", script, "--no-browser", "--port", str(port), "--ip", "127.0.0.1"], cwd=folder,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                            start_new_session=True)
    fd = proc.stdout.fileno()
    arrivals, text, phases, served = [(0.0, "")], bytearray(), {}, None
    prefix = f"{Path(script).name}: ["
    try:
        while served is None:
            ready, _, _ = select.select([fd], [], [], 1.0)
            if not ready:
                if proc.poll() is not None:
                    break
                continue
            chunk = os.read(fd, 65536)
            if not chunk:
                break
            now = time.monotonic() - t0
            before = len(text)
            text += chunk
            lines = bytes(text[max(0, before - 200):]).decode(errors="replace").splitlines()
            arrivals.append((now, lines[-1][:100] if lines else ""))
            for line in lines:
                if line.startswith(prefix) and line[len(prefix) - 1:len(prefix) + 3] not in phases:
                    phases[line[len(prefix) - 1:len(prefix) + 3]] = round(now, 2)
                if f"127.0.0.1:{port}/" in line:
                    served = now
    finally:
        try:
            os.killpg(proc.pid, signal.SIGTERM)
        except ProcessLookupError:
            pass
        proc.wait(timeout=60)
    shutil.rmtree(folder, ignore_errors=True)
    if served is None:
        raise SystemExit(f"{what} ({installer}) did not serve JupyterLab (exit {proc.returncode}):\n"
                         f"{text.decode(errors='replace')[-3000:]}")
    gaps = [(b[0] - a[0], a) for a, b in zip(arrivals, arrivals[1:])]
    longest, (at, before_line) = max(gaps)
    said = text.decode(errors="replace")
    jl = said.find("starting JupyterLab")
    return {"what": what, "installer": installer, "seconds_to_serving": round(served, 2),
            "longest_silence_s": round(longest, 2), "silence_starts_at_s": round(at, 2),
            "silence_after": before_line.strip(), "phases_s": phases,
            "jupyterlab_progress_lines": said[jl:].count("JupyterLab is starting") if jl >= 0 else 0}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--load", type=int, default=0, metavar="N", help="run N busy processes during the measurement")
    ap.add_argument("--pip", action="store_true", help="also start.sh with pip alone (the baseline)")
    ap.add_argument("--no-warmup", action="store_true", help="measure the first runs (caches known warm)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    busy = [subprocess.Popen([sys.executable, "-c", BUSY]) for _ in range(args.load)]
    try:
        with tempfile.TemporaryDirectory(prefix="bench-start-") as tmp:
            where = Path(tmp)
            handout, checkout = make_handout(where), make_checkout(where)
            plan = [(handout, "start.sh", "uv"), (checkout, "course.sh", "uv")]
            if args.pip:
                plan.append((handout, "start.sh", "pip"))
            if not args.no_warmup:
                for installer in sorted({i for _, _, i in plan}):
                    print(f"warm-up ({installer}) ...", file=sys.stderr, flush=True)
                    run_start(handout, where, "start.sh", installer)
            load = os.getloadavg()
            results = []
            for source, what, installer in plan:
                results.append(run_start(source, where, what, installer))
                print(json.dumps(results[-1]), file=sys.stderr, flush=True)
            load_end = os.getloadavg()
    finally:
        for p in busy:
            p.kill()
            p.wait()
    summary = {"load_at_start": [round(x, 2) for x in load], "load_at_end": [round(x, 2) for x in load_end],
               "busy_processes": args.load, "cores": os.cpu_count(), "runs": results}
    by = {(r["what"], r["installer"]): r for r in results}
    if ("start.sh", "pip") in by:
        summary["ratio_uv_over_pip"] = round(by["start.sh", "uv"]["seconds_to_serving"]
                                             / by["start.sh", "pip"]["seconds_to_serving"], 3)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(f"load average {summary['load_at_start']} at the start, {summary['load_at_end']} at the end, on "
              f"{summary['cores']} cores ({args.load} busy processes of the benchmark's)")
        for r in results:
            print(f"  {r['what']:>9} ({r['installer']}): serving after {r['seconds_to_serving']:6.1f} s, longest "
                  f"silence {r['longest_silence_s']:.1f} s (from {r['silence_starts_at_s']:.1f} s, after "
                  f"{r['silence_after'][:60]!r}), {r['jupyterlab_progress_lines']} line(s) while JupyterLab "
                  f"started, phases {r['phases_s']}")
        if "ratio_uv_over_pip" in summary:
            print(f"start.sh uv/pip {summary['ratio_uv_over_pip']:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
