"""A student's failure is the student's; the grader's never is (issue 28, item 3).

Each route by which a submission once turned its own grade into "not graded: grader error,
rerun" (or killed its parent, the grader or a classmate) is tried for real, in the sandbox with
bubblewrap and without it, as the grader's user (root in CI) and as an ordinary user:

* an answer frame whose JSON header nests 200,000 levels deep (RecursionError in the decoder),
  one holding a 401-digit number (OverflowError), one holding a pickled array whose unpickling
  would run code in the grader: each is that check's unreadable answer;
* ``fcntl`` F_SETOWN / F_SETOWN_EX / F_SETSIG with ``O_ASYNC``, ``ioctl`` FIOSETOWN / SIOCSPGRP,
  a signal to the process group: refused by seccomp (EPERM), the harness and a process of the
  grader's user outside survive;
* statements that sleep while they load (default arguments): charged to the submission (its
  statements skipped), never a grader retry;

and on the grader's side: ``ast.parse`` never runs in two threads at once (python/cpython#106905),
and a sandbox that dies after answering some checks leaves the others "not graded", never 0.
"""

from __future__ import annotations

import ast
import csv
import json
import os
import shutil
import subprocess
import threading
import time

import pytest

from ci import missing
from dtscal_lib.grading import grade as grade_module
from dtscal_lib.grading import loader, sandbox
from dtscal_lib.grading.errors import GRADER_ERROR
from dtscal_lib.grading.grade import GRADER_ERROR_STATUS, grade_file
from dtscal_lib.grading.material import Material
from dtscal_lib.grading.report import text
from nbtools import ROOT
from sandbox_user import readable_python, use
from unprivileged import run_unprivileged, shared_tmp

CORRECT = ROOT / "solutions" / "02_homography.ipynb"


@pytest.fixture(scope="module", autouse=True)
def bubblewrap():
    ok, why = sandbox.bwrap_available()
    if not ok:
        missing(f"bubblewrap does not run here ({why}); scripts/install-sandbox.sh installs it")


@pytest.fixture(scope="module")
def material():
    m = Material.load(ROOT)
    m.checks("02_homography")
    return m


# --------------------------------------------------------------------------- what student code does
FORGE = '''
import io
import json
import os
import struct
import fcntl
import signal

import numpy as np


def _send(header, blob=b""):
    """A forged answer frame on every descriptor (the worker's answer pipe is one), then exit 0."""
    answer = struct.pack(">I", len(header)) + header + blob
    msg = memoryview(answer + struct.pack(">Q", len(answer)) + b"DTSCAL01")
    for fd in range(3, 64):
        try:
            view = msg
            while view:
                view = view[os.write(fd, view):]
        except OSError:
            pass
    os._exit(0)


def deep_json(target):
    _send(b'{"calls": ' + b"[" * 200000 + b"]" * 200000 + b', "blobs": []}')


def big_number(target):
    _send(b'{"calls": [{"ok": false, "error": "x", "time": 1' + b"0" * 400 + b'}], "blobs": []}')


class _Payload:
    def __reduce__(self):
        return (os.mkdir, (MARK,))


def pickled(target):
    buf = io.BytesIO()
    np.save(buf, np.array([_Payload()], dtype=object), allow_pickle=True)
    blob = buf.getvalue()
    head = json.dumps({"calls": [{"ok": True, "value": {"kind": "array", "blob": 0}}], "blobs": [len(blob)]})
    _send(head.encode(), blob)


def _whom(target):
    return os.getppid() if target == 0 else target


def _async(r, w):
    fcntl.fcntl(r, fcntl.F_SETFL, fcntl.fcntl(r, fcntl.F_GETFL) | os.O_ASYNC)
    os.write(w, b"x")
    time.sleep(0.05)
    return 1.0


def f_setown(target):
    r, w = os.pipe()
    fcntl.fcntl(r, fcntl.F_SETOWN, _whom(target))
    return _async(r, w)


def f_setown_ex(target):
    r, w = os.pipe()
    fcntl.fcntl(r, 15, struct.pack("ii", 1, _whom(target)))  # F_SETOWN_EX, F_OWNER_PID
    return _async(r, w)


def f_setsig(target):
    r, w = os.pipe()
    fcntl.fcntl(r, 10, signal.SIGKILL)  # F_SETSIG: the owner (this process) would get SIGKILL
    return 1.0


def fiosetown(target):
    r, w = os.pipe()
    fcntl.ioctl(r, 0x8901, struct.pack("i", _whom(target)))
    fcntl.ioctl(r, 0x5452, struct.pack("i", 1))  # FIOASYNC
    return _async(r, w)


def siocspgrp(target):
    r, w = os.pipe()
    fcntl.ioctl(r, 0x8902, struct.pack("i", _whom(target)))
    return _async(r, w)


def process_group(target):
    os.killpg(0, signal.SIGKILL)
    return 1.0


def survivor(target):
    return 7.0
'''
FRAMES = ("deep_json", "big_number", "pickled")
SIGNALS = ("f_setown", "f_setown_ex", "f_setsig", "fiosetown", "siocspgrp", "process_group")


def _routes(mark: str, victim: int) -> str:
    """Every route in one sandbox: each check a route, at the harness (0) then at ``victim``;
    the last check answers 7.0 only if the harness survived them all."""
    calls = [(r, (0,)) for r in FRAMES + SIGNALS] + [(r, (victim,)) for r in SIGNALS] + [("survivor", (0,))]
    statements = [("import time", 1), (f"MARK = {mark!r}", 2), (FORGE, 3)]
    run = sandbox.run_calls(statements, [sandbox.CheckJob(id=i, calls=[c], wall=10.0, cpu=5)
                                         for i, c in enumerate(calls)])
    out = []
    for i, (name, _) in enumerate(calls):
        cr = run.checks[i]
        c = cr.calls[0] if cr.calls else None
        said = cr.failure or (c.error if not c.ok else f"value {c.value!r} {c.note}")
        out.append(f"{name}: {said}")
    return f"{run.notes['mode']}\n" + "\n".join(out)


def _assert_held(got: str, mark) -> None:
    lines = dict(ln.split(": ", 1) for ln in got.split("\n")[1:])
    assert "value array(7.)" in lines["survivor"], got  # the harness answered after every route
    for r in FRAMES:  # the frame is that check's unreadable answer (the student's), nothing ran
        assert "ended the process" in lines[r] or "unreadable" in lines[r], got
    for r in SIGNALS:
        assert "Operation not permitted" in lines[r], got
    assert not os.path.exists(mark), "the pickled payload ran in the grader"


@pytest.fixture()
def victim():
    """A process of the grader's user outside the sandbox (a classmate's harness, the grader)."""
    p = subprocess.Popen(["sleep", "120"])
    yield p
    p.kill()
    p.wait()


@pytest.mark.parametrize("mode", ["bubblewrap", "bare"])
def test_frames_and_signals_are_the_students(mode, tmp_path, victim, monkeypatch):
    monkeypatch.setattr(sandbox, "MODE", mode)
    mark = str(tmp_path / "payload-ran")
    got = _routes(mark, victim.pid)
    assert got.startswith(mode), got
    _assert_held(got, mark)
    assert victim.poll() is None, "a process outside the sandbox was killed"


def test_frames_and_signals_as_an_ordinary_user(victim):
    with shared_tmp() as d:
        python = readable_python(d)
        mark = str(d / "payload-ran")
        os.chmod(d, 0o777)

        def attempt():
            use(*python)
            out = []
            for mode in ("bubblewrap", "bare"):
                sandbox.MODE = mode
                out.append(_routes(mark, victim.pid))
            return "\n\n".join(out)

        ok, got = run_unprivileged(attempt, timeout=240)
        assert ok, got
        for part, mode in zip(got.split("\n\n"), ("bubblewrap", "bare")):
            assert part.startswith(mode), got
            _assert_held(part, mark)
    assert victim.poll() is None


def test_slow_loading_is_charged_to_the_submission(monkeypatch):
    """Eight definitions whose default arguments sleep: once the harness's load budget is spent,
    their statements are skipped (said to the student); the checks of what loaded are answered,
    and no grader deadline fires (before: 6 min 10 s of retries, then "grader error")."""
    monkeypatch.setattr(sandbox, "LOAD_WALL_S", 2.0)
    slow = [(f"def slow{k}(x=time.sleep(3)):\n    return x", 10 + 3 * k) for k in range(8)]
    statements = [("import time", 1), ("def ok():\n    return 7.0", 2), *slow]
    run = sandbox.run_calls(statements, [sandbox.CheckJob(id=0, calls=[("ok", ())], wall=10.0, cpu=5),
                                         sandbox.CheckJob(id=1, calls=[("slow7", ())], wall=10.0, cpu=5)])
    assert float(run.checks[0].calls[0].value) == 7.0
    assert "defines no function slow7" in run.checks[1].calls[0].error
    assert {k for k, _ in run.load_errors} == set(range(2, 10)), run.load_errors


# --------------------------------------------------------------------------- the grader's own failures
def test_parse_never_runs_in_two_threads_at_once(tmp_path, monkeypatch):
    """``ast.parse`` is not thread-safe in CPython (python/cpython#106905: SystemError under
    --jobs 2, a correct submission graded 0): the loader parses one source at a time."""
    real, inside, most = ast.parse, [0], [0]
    lock = threading.Lock()

    def watched(*a, **k):
        with lock:
            inside[0] += 1
            most[0] = max(most[0], inside[0])
        try:
            time.sleep(0.0005)
            return real(*a, **k)
        finally:
            with lock:
                inside[0] -= 1

    monkeypatch.setattr(ast, "parse", watched)
    p = tmp_path / "02_homography.ipynb"
    shutil.copy(CORRECT, p)
    threads = [threading.Thread(target=loader.load_submission, args=(p,)) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert most[0] == 1, f"{most[0]} parses at once"


def test_a_transient_parser_systemerror_is_tried_again_not_charged(tmp_path, monkeypatch):
    """A compile outside the lock (the first import of a module in another thread) can still meet a parse: the
    SystemError of python/cpython#106905 seen in CI on a correct corpus file ("the submission could not be
    read: AST constructor recursion depth mismatch", 0/30). It is the interpreter's: the parse is tried again."""
    real, calls = ast.parse, [0]

    def flaky(*a, **k):
        calls[0] += 1
        if calls[0] <= 2:
            raise SystemError("AST constructor recursion depth mismatch (before=33, after=62)")
        return real(*a, **k)

    monkeypatch.setattr(ast, "parse", flaky)
    p = tmp_path / "02_homography.ipynb"
    shutil.copy(CORRECT, p)
    sub = loader.load_submission(p)
    assert sub.functions and calls[0] >= 3


def test_a_sandbox_dying_midway_leaves_the_rest_not_graded(tmp_path, material, monkeypatch):
    """Every sandbox dies right after its first answer (a failure of the grader's side): the checks
    answered count, the functions with an unanswered check read "grader error", no check is 0."""
    real = sandbox._next_frame
    answered = [0]

    def dying(fd, buf, deadline):
        if answered[0]:
            answered[0] = 0
            return None  # the sandbox ended
        got = real(fd, buf, deadline)
        if got is not None and got[0].get("event") == "check":
            answered[0] = 1
        return got

    monkeypatch.setattr(sandbox, "_next_frame", dying)
    monkeypatch.setattr(grade_module, "GRADER_RETRY_PAUSE_S", (0.0, 0.0))
    monkeypatch.setattr(sandbox, "RETRY_PAUSE_S", 0.0)
    p = tmp_path / "02_homography.ipynb"
    shutil.copy(CORRECT, p)
    res = grade_file(p, material, "02_homography")
    assert res.grader_error, text(res)
    statuses = {f.name: f.status for f in res.functions}
    assert GRADER_ERROR_STATUS in statuses.values(), text(res)
    for f in res.functions:
        for t in f.tests:
            if f.status == GRADER_ERROR_STATUS:
                assert t.output.startswith(GRADER_ERROR), text(res)
            else:
                assert t.score == t.max_score, text(res)  # answered before the failure: counted


# --------------------------------------------------------------------------- a class
SABOTAGE = {  # apply_homography's body: each route above, inside a whole submission
    "deep": "    deep_json(0)\n",
    "bignum": "    big_number(0)\n",
    "pickle": "    pickled(0)\n",
    "setown": "    f_setown(0)\n    return pts\n",
    "pgroup": "    process_group(0)\n    return pts\n",
}
def test_a_class_of_saboteurs_and_correct_classmates(tmp_path, monkeypatch):
    """--jobs 2: each sabotage costs its author's apply_homography only; no "grader error"
    anywhere, the correct classmates and the saboteurs' own estimate_homography at full marks."""
    from dtscal_lib.cli import main as dtscal

    klass = tmp_path / "class"
    mark = tmp_path / "payload-ran"
    nb = json.loads(CORRECT.read_text())
    for name, body in SABOTAGE.items():  # the solution, with a last cell that redefines apply_homography
        (klass / name).mkdir(parents=True)
        src = f"import time\nMARK = {str(mark)!r}\n{FORGE}\n\ndef apply_homography(H, pts):\n{body}"
        cell = {"cell_type": "code", "metadata": {}, "execution_count": None, "outputs": [], "source": src}
        (klass / name / "02_homography.ipynb").write_text(json.dumps(dict(nb, cells=nb["cells"] + [cell])))
    for name in ("ann", "ben"):
        (klass / name).mkdir()
        shutil.copy(CORRECT, klass / name / "02_homography.ipynb")
    out = tmp_path / "g.csv"
    assert dtscal(["grade", str(klass), "--jobs", "2", "--csv", str(out), "-q"]) == 0
    rows = {r["student"]: r for r in csv.DictReader(out.open())}
    assert GRADER_ERROR_STATUS not in out.read_text()
    for name in ("ann", "ben"):
        assert rows[name]["total"] == rows[name]["max"], rows[name]
    for name in SABOTAGE:
        assert rows[name]["apply_homography"] == "0", rows[name]
        assert float(rows[name]["estimate_homography"]) == 10, rows[name]
    assert not mark.exists()
