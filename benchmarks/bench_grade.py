"""Benchmark: the autograder on one notebook and on a whole class.

1. One notebook: ``dtscal grade`` on the solution of notebook 04 (the heaviest: three
   functions, 640x480 rectification maps), end to end as an instructor runs it (process
   start, grading material, references, sandbox). Target: < 10 s wall.
2. A class of 60 students x 5 notebooks (300 submissions) with ``--jobs 2``. Each
   student's notebook is drawn (seeded) from the solution (55 %), a buggy implementation of
   the test corpus (35 %) or the untouched student notebook (10 %). Target: < 60 s wall, sandbox included.
3. Baseline, measured in the same run: ``--jobs 1`` against ``--jobs 2`` on the first
   10 students (50 submissions); the ratio says what the second process buys.
5. The grader's own peak memory (its ru_maxrss) on a class of notebook-02 solutions, beside the same
   class whose apply_homography answers just under the 64 MB cap per check. Target: <= 2x.
4. The sandbox's cost: the same class graded in this process with ``--jobs 2``, once in
   bubblewrap and once with the harness run as a bare process (the benchmark switches
   ``sandbox.MODE``; the grader has no such option). Target: bubblewrap <= 1.5x bare; prints
   the cost per submission and per check.

Run::

    .venv/bin/python benchmarks/bench_grade.py [--students 60] [--subset 10] [--json]
"""

from __future__ import annotations

import argparse
import json
import random
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CORPUS = ROOT / "tests" / "grading_corpus"
ASSIGNMENTS = ("01_pinhole_projection", "02_homography", "03_intrinsic_calibration",
               "04_distortion_rectification", "05_extrinsic_calibration")


def make_class(folder: Path, students: int, seed: int = 9) -> int:
    rng = random.Random(seed)
    n = 0
    for s in range(students):
        d = folder / f"student{s:03d}"
        d.mkdir(parents=True)
        for a in ASSIGNMENTS:
            r = rng.random()
            if r < 0.55:
                shutil.copy(ROOT / "solutions" / f"{a}.ipynb", d / f"{a}.ipynb")
            elif r < 0.90:
                shutil.copy(rng.choice(sorted(CORPUS.glob(f"{a}__*.py"))), d / f"{a}.py")
            else:
                shutil.copy(ROOT / "notebooks" / f"{a}.ipynb", d / f"{a}.ipynb")
            n += 1
    return n


def grade(target: Path, jobs: int, out: Path) -> float:
    t0 = time.perf_counter()
    run = subprocess.run([sys.executable, "-m", "dtscal_lib.cli", "grade", str(target), "--jobs", str(jobs),
                          "--csv", str(out / f"summary_{target.name}_{jobs}.csv"), "-q"],
                         cwd=ROOT, capture_output=True, text=True)
    took = time.perf_counter() - t0
    if run.returncode != 0:
        sys.exit(f"dtscal grade failed:\n{run.stderr[-2000:]}")
    return took


def sandbox_cost(cls: Path) -> dict:
    """Grade ``cls`` in this process with --jobs 2, in bubblewrap and bare; (seconds, counts)."""
    sys.path.insert(0, str(ROOT))
    from dtscal_lib.grading import grade as grade_module
    from dtscal_lib.grading import sandbox
    from dtscal_lib.grading.classroom import grade_all, roster
    from dtscal_lib.grading.material import Material

    material = Material.load(ROOT)
    items = roster(cls).items
    counts = {"sandboxes": 0, "checks": 0}
    real = grade_module.run_calls

    def counted(statements, checks, **kw):
        counts["sandboxes"] += 1
        counts["checks"] += len(checks)
        return real(statements, checks, **kw)

    grade_module.run_calls = counted
    out = {}
    try:
        for mode in ("bare", "bubblewrap", "bare", "bubblewrap"):  # twice each, interleaved: load drifts
            sandbox.MODE = mode
            counts.update(sandboxes=0, checks=0)
            t0 = time.perf_counter()
            results = grade_all(items, material, jobs=2)
            took = time.perf_counter() - t0
            out[mode] = min(out.get(mode, took), took)
            out[f"{mode}_score"] = round(sum(r.score for r in results), 2)
    finally:
        grade_module.run_calls = real
        sandbox.MODE = None
    out.update(counts)
    return out


#: a last cell that makes apply_homography answer just under the 64 MB cap of a check (the
#: budget is per worker process, i.e. per check): the answers a student chooses to make large
BIG_ANSWERS = """
import numpy as np


def apply_homography(H, pts):
    left = apply_homography.__dict__.setdefault("left", 62 * 2 ** 20)
    n = min(left // 2, 32 * 2 ** 20) // 8
    apply_homography.left = left - 8 * n
    return np.zeros(n)
"""

_PEAK = ("import resource, sys; from dtscal_lib.cli import main; rc = main(sys.argv[1:]); "
         "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, file=sys.stderr); sys.exit(rc)")


def peak_memory(tmp: Path, copies: int = 6) -> dict:
    """The grading process's peak memory (MB, its own ru_maxrss: not the sandboxes') on a class of
    ``copies`` notebook-02 solutions, and on the same class with answers just under the cap."""
    nb = json.loads((ROOT / "solutions" / "02_homography.ipynb").read_text())
    big = dict(nb, cells=nb["cells"] + [{"cell_type": "code", "metadata": {}, "execution_count": None,
                                         "outputs": [], "source": BIG_ANSWERS}])
    out = {}
    for name, doc in (("solution", nb), ("big_answers", big)):
        cls = tmp / f"mem_{name}"
        for k in range(copies):
            (cls / f"s{k}").mkdir(parents=True)
            (cls / f"s{k}" / "02_homography.ipynb").write_text(json.dumps(doc))
        run = subprocess.run([sys.executable, "-c", _PEAK, "grade", str(cls), "--jobs", "2", "-q"], cwd=ROOT,
                             capture_output=True, text=True)
        out[name] = int(run.stderr.strip().splitlines()[-1]) / 1024
    return out


def startup_cost(rounds: int = 15) -> dict:
    """Median seconds of one sandbox with one trivial check, in bubblewrap and bare (interleaved)."""
    import statistics

    sys.path.insert(0, str(ROOT))
    from dtscal_lib.grading import sandbox

    statements = [("import numpy as np", 1), ("def f(x):\n    return np.asarray(x) * 2", 2)]
    times = {"bubblewrap": [], "bare": []}
    try:
        for _ in range(rounds):
            for mode in times:
                sandbox.MODE = mode
                t0 = time.perf_counter()
                sandbox.run_calls(statements, [sandbox.CheckJob(id=0, calls=[("f", (3.0,))], wall=10, cpu=5)])
                times[mode].append(time.perf_counter() - t0)
    finally:
        sandbox.MODE = None
    return {m: statistics.median(v) for m, v in times.items()}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--students", type=int, default=60)
    ap.add_argument("--subset", type=int, default=10, help="students in the jobs 1 vs 2 comparison")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench-grade-"))
    try:
        one = grade(ROOT / "solutions" / "04_distortion_rectification.ipynb", 1, tmp)
        cls = tmp / "class"
        n = make_class(cls, args.students)
        full = grade(cls, 2, tmp)
        sub = tmp / "subset"
        sub.mkdir()
        for d in sorted(cls.iterdir())[: args.subset]:
            shutil.copytree(d, sub / d.name)
        n_sub = sum(1 for _ in sub.rglob("0*"))
        serial = grade(sub, 1, tmp)
        parallel = grade(sub, 2, tmp)
        cost = sandbox_cost(cls)
        start = startup_cost()
        mem = peak_memory(tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    res = {"one_notebook_s": round(one, 2), "class_submissions": n, "class_jobs2_s": round(full, 1),
           "class_per_submission_s": round(full / n, 3), "subset_submissions": n_sub,
           "subset_jobs1_s": round(serial, 1), "subset_jobs2_s": round(parallel, 1),
           "speedup_jobs2_vs_jobs1": round(serial / parallel, 2),
           "class_jobs2_bubblewrap_s": round(cost["bubblewrap"], 1), "class_jobs2_bare_s": round(cost["bare"], 1),
           "bubblewrap_vs_bare": round(cost["bubblewrap"] / cost["bare"], 2),
           "sandbox_cost_per_submission_ms": round(1000 * (cost["bubblewrap"] - cost["bare"]) / cost["sandboxes"], 1),
           "sandbox_cost_per_check_ms": round(1000 * (cost["bubblewrap"] - cost["bare"]) / cost["checks"], 2),
           "same_scores": cost["bubblewrap_score"] == cost["bare_score"],
           "one_check_bubblewrap_ms": round(1000 * start["bubblewrap"], 1),
           "one_check_bare_ms": round(1000 * start["bare"], 1),
           "grader_peak_mb_solutions": round(mem["solution"], 1),
           "grader_peak_mb_big_answers": round(mem["big_answers"], 1),
           "grader_peak_ratio": round(mem["big_answers"] / mem["solution"], 2)}
    if args.json:
        print(json.dumps(res))
    else:
        print(f"one notebook (04, solution), end to end: {one:.2f} s   (target < 10 s)")
        print(f"class of {args.students} students, {n} submissions, --jobs 2: {full:.1f} s "
              f"({full / n:.2f} s per submission; target < 60 s, sandbox included)")
        print(f"subset of {n_sub} submissions: --jobs 1 {serial:.1f} s, --jobs 2 {parallel:.1f} s: "
              f"{serial / parallel:.2f}x faster with 2 processes")
        print(f"the same class in this process, --jobs 2: bubblewrap {cost['bubblewrap']:.1f} s, checks as bare "
              f"processes {cost['bare']:.1f} s: {res['bubblewrap_vs_bare']:.2f}x (target <= 1.5x); the sandbox "
              f"costs {res['sandbox_cost_per_submission_ms']:.0f} ms per submission ({cost['sandboxes']} sandboxes), "
              f"{res['sandbox_cost_per_check_ms']:.1f} ms per check ({cost['checks']} checks); "
              f"same scores: {res['same_scores']}")
        print(f"one submission with one trivial check (median of 15): bubblewrap "
              f"{res['one_check_bubblewrap_ms']:.0f} ms, bare {res['one_check_bare_ms']:.0f} ms: "
              f"bubblewrap's start costs "
              f"{res['one_check_bubblewrap_ms'] - res['one_check_bare_ms']:.0f} ms per submission")
        print(f"the grading process's peak memory, a class of 6 notebook-02 submissions, --jobs 2: the solution "
              f"{res['grader_peak_mb_solutions']:.0f} MB; answers just under the 64 MB cap per check "
              f"{res['grader_peak_mb_big_answers']:.0f} MB: {res['grader_peak_ratio']:.2f}x (target <= 2x)")
    ok = one < 10 and full < 60 and res["bubblewrap_vs_bare"] <= 1.5 and res["same_scores"] and \
        res["grader_peak_ratio"] <= 2
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
