#!/usr/bin/env python3
"""Mutation check: plant realistic bugs one at a time and see which tests catch each.

The bugs are kept in ``tests/mutations/*.toml`` as sed-style patches::

    [[mutation]]
    name = "camera_info K transposed"
    file = "dtscal_lib/robot.py"
    pattern = '"K": [float(v) for v in calib.K.ravel()]'    # literal text, found exactly once
    replacement = '"K": [float(v) for v in calib.K.T.ravel()]'
    tests = ["tests/test_camera_info.py"]                     # what must catch it (files, node ids, options)
    why = "COMMIT sends K transposed: the robot's camera_info is wrong"
    also = [{file = "...", pattern = "...", replacement = "..."}]   # optional: more places of the same bug

For each mutation: check the pattern occurs exactly once, write the mutated file, run
``pytest -x -q`` on the named tests only (no xdist, no bytecode written), restore the file (byte
for byte, with its modification time), and record whether the run failed (caught). Before the
mutations, each distinct test selection runs once unmutated (the baseline): a selection that fails
without a bug would make every bug look caught, and is reported instead. CI does not run this
script; its last table is in tests/README.md (``--readme`` rewrites it there).

Usage::

    .venv/bin/python scripts/mutate.py                  # every mutation, with the baseline
    .venv/bin/python scripts/mutate.py -k verdict       # only mutations whose name contains "verdict"
    .venv/bin/python scripts/mutate.py --list           # the list, nothing run
    .venv/bin/python scripts/mutate.py --readme         # and write the table into tests/README.md

Exit status: 0 when every mutation is caught and every baseline passes, 1 otherwise.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MUTATIONS = ROOT / "tests" / "mutations"
README = ROOT / "tests" / "README.md"
BEGIN, END = "<!-- mutation table: begin -->", "<!-- mutation table: end -->"
#: a safety net per run (the slowest selection takes about a minute on 2 cores)
TIMEOUT_S = 900


def load() -> list[dict]:
    out = []
    for path in sorted(MUTATIONS.glob("*.toml")):
        for m in tomllib.loads(path.read_text(encoding="utf-8")).get("mutation", []):
            missing = {"name", "file", "pattern", "replacement", "tests"} - set(m)
            if missing:
                sys.exit(f"{path.name}: mutation {m.get('name', '?')!r} lacks {', '.join(sorted(missing))}")
            out.append({**m, "source": path.name})
    return out


def run_tests(tests: list[str]) -> tuple[int, str]:
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")
    cmd = [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "-p", "no:xdist", "-p", "no:randomly",
           "--no-header", *tests]
    try:
        p = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        return -1, "timed out"
    lines = [ln for ln in p.stdout.splitlines() if ln.strip()]
    failed = [ln.split(" ")[1] for ln in lines if ln.startswith(("FAILED ", "ERROR "))]
    return p.returncode, (failed[0] if failed else (lines[-1] if lines else p.stderr.strip()[-200:]))


def mutate_and_run(m: dict) -> tuple[str, str]:
    patches = [m] + list(m.get("also", []))  # one bug may need two places (a limit and its backstop)
    saved = {}
    for p in patches:
        path = ROOT / p["file"]
        if path not in saved:
            saved[path] = (path.read_bytes(), os.stat(path))
    texts = {path: raw.decode("utf-8") for path, (raw, _) in saved.items()}
    for p in patches:
        path = ROOT / p["file"]
        n = texts[path].count(p["pattern"])
        if n != 1:
            return "STALE", f"the pattern occurs {n} times in {p['file']} (must be exactly once)"
        texts[path] = texts[path].replace(p["pattern"], p["replacement"])
    try:
        for path, text in texts.items():
            path.write_text(text, encoding="utf-8")
        code, detail = run_tests(m["tests"])
    finally:
        for path, (raw, st) in saved.items():
            path.write_bytes(raw)
            os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))
    if code == 0:
        return "MISSED", "every named test passed"
    if code == 5:
        return "STALE", "no test collected: " + detail
    if code == -1:
        return "caught (timeout)", detail
    return "caught", detail


def table(rows: list[tuple[dict, str, str]]) -> str:
    lines = ["| # | planted bug | file | caught by | result |", "|---|---|---|---|---|"]
    for i, (m, status, detail) in enumerate(rows, 1):
        by = detail if status.startswith("caught") else "; ".join(m["tests"])
        files = ", ".join(dict.fromkeys(f"`{p['file']}`" for p in [m, *m.get("also", [])]))
        lines.append(f"| {i} | {m['name']} | {files} | `{by}` | {status} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-k", dest="select", default="", help="only mutations whose name contains this text")
    ap.add_argument("--list", action="store_true", help="print the mutations and exit")
    ap.add_argument("--no-baseline", action="store_true", help="skip the unmutated runs")
    ap.add_argument("--readme", action="store_true", help=f"write the table into {README.relative_to(ROOT)}")
    a = ap.parse_args(argv)
    ms = [m for m in load() if a.select.lower() in m["name"].lower()]
    if a.list:
        for m in ms:
            print(f"{m['name']:55} {m['file']:38} {' '.join(m['tests'])}")
        return 0
    files = sorted({p["file"] for m in ms for p in [m, *m.get("also", [])]})
    dirty = subprocess.run(["git", "status", "--porcelain", "--", *files], cwd=ROOT,
                           capture_output=True, text=True).stdout.strip()
    if dirty:
        print(f"uncommitted changes in the files to mutate (commit them first):\n{dirty}", file=sys.stderr)
        return 1
    t0 = time.monotonic()
    ok = True
    if not a.no_baseline:
        for sel in sorted({tuple(m["tests"]) for m in ms}):
            code, detail = run_tests(list(sel))
            print(f"baseline {' '.join(sel)}: {'passes' if code == 0 else 'FAILS: ' + detail}", flush=True)
            ok &= code == 0
    rows = []
    for m in ms:
        status, detail = mutate_and_run(m)
        rows.append((m, status, detail))
        print(f"{status:8} {m['name']}: {detail}", flush=True)
        ok &= status.startswith("caught")
    out = table(rows)
    caught = sum(s.startswith("caught") for _, s, _ in rows)
    summary = (f"{caught} of {len(rows)} planted bugs caught ({time.strftime('%Y-%m-%d')}, "
               f"{(time.monotonic() - t0) / 60:.0f} min on this machine, load {os.getloadavg()[0]:.1f})")
    print("\n" + out + "\n\n" + summary)
    if a.readme and not a.select:
        doc = README.read_text(encoding="utf-8")
        head, rest = doc.split(BEGIN, 1)
        README.write_text(head + BEGIN + "\n" + out + "\n\n" + summary + "\n" + END + rest.split(END, 1)[1],
                          encoding="utf-8")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
