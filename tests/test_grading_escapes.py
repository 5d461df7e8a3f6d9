"""Escapes from the grading sandbox, each tried for real: the test fails if the file outside
appears, a process survives, another submission is hurt or a solving routine does the work.

The sandbox's barriers (see ``docs/grading-sandbox.md``): Landlock (writes only in the
working folder, no exec, material unreadable, no signals outside the submission), PID /
mount / network namespaces, a fresh uid per submission under root, a supervisor that owns
the control pipe. The file escapes are tried as the grader's user (root in CI) and, where
the interpreter is readable by another user, as ``nobody``.
"""

from __future__ import annotations

import os
import resource
import shutil
import sys
import tempfile
import threading
from pathlib import Path

import pytest

from dtscal_lib.grading import sandbox
from dtscal_lib.grading.child import _world_readable
from dtscal_lib.grading.grade import grade_file
from dtscal_lib.grading.material import Material
from dtscal_lib.grading.report import text
from nbtools import ROOT
from unprivileged import run_unprivileged

CASES = ROOT / "grading" / "cases.py"
SECRET = "POINTS_PER_FUNCTION"  # a word of the hidden cases file


@pytest.fixture()
def outside():
    """A folder outside the sandbox that everyone may write (so only the sandbox stops a write)."""
    d = Path(tempfile.mkdtemp(prefix="dtscal-outside-"))
    os.chmod(d, 0o777)
    yield d
    shutil.rmtree(d, ignore_errors=True)


def _run(defs: str, wall=10.0, cpu=5, calls=(("f", ()),)):
    statements = [("import os\nimport sys\nimport time\nimport signal", 1), (defs, 5)]
    checks = [{"id": i, "calls": [c], "wall": wall, "cpu": cpu} for i, c in enumerate(calls)]
    return sandbox.run_calls(statements, checks, blocked_paths=[ROOT / "grading", ROOT / "solutions"])


def _value(run, cid=0):
    cr = run.checks[cid]
    assert not cr.failure, cr.failure
    c = cr.calls[0]
    return c.value if c.ok else c.error


ESCAPES = {
    # second path outside (the audit hook once checked the first path only)
    "rename": "open('a', 'w').write('x')\n    os.rename('a', OUT + '/escaped')",
    "replace": "open('a', 'w').write('x')\n    os.replace('a', OUT + '/escaped')",
    "symlink": "os.symlink('/etc/hostname', OUT + '/escaped')",
    "link": "open('a', 'w').write('x')\n    os.link('a', OUT + '/escaped')",
    # the same through a folder descriptor: the path the audit hook sees looks local
    "rename_dir_fd": "fd = os.open(OUT, os.O_RDONLY)\n    open('a', 'w').write('x')\n"
                     "    os.rename('a', 'escaped', dst_dir_fd=fd)",
    "link_dir_fd": "fd = os.open(OUT, os.O_RDONLY)\n    open('a', 'w').write('x')\n"
                   "    os.link('a', 'escaped', dst_dir_fd=fd)",
    "symlink_dir_fd": "fd = os.open(OUT, os.O_RDONLY)\n    os.symlink('/etc/hostname', 'escaped', dir_fd=fd)",
    "open_dir_fd": "fd = os.open(OUT, os.O_RDONLY)\n"
                   "    os.close(os.open('escaped', os.O_WRONLY | os.O_CREAT, 0o644, dir_fd=fd))",
    "mkdir_dir_fd": "fd = os.open(OUT, os.O_RDONLY)\n    os.mkdir('escaped', dir_fd=fd)",
}


def _try_escape(kind: str, out: str) -> str:
    body = ESCAPES[kind]
    run = _run(f"OUT = {out!r}\n\ndef f():\n    {body}\n    return 1.0\n")
    return str(_value(run))


@pytest.mark.parametrize("kind", list(ESCAPES))
def test_no_file_outside_the_working_folder(kind, outside):
    got = _try_escape(kind, str(outside))
    assert not (outside / "escaped").exists(), got
    assert os.listdir(outside) == [], got
    assert "Error" in got, got  # refused, and the student is told


def _interpreter_readable_by_others() -> bool:
    return all(_world_readable(p) for p in (sys.executable, os.path.dirname(os.__file__), str(ROOT)))


@pytest.mark.parametrize("kind", ["rename", "link_dir_fd", "open_dir_fd"])
def test_no_file_outside_as_unprivileged_user(kind, outside):
    if os.geteuid() == 0 and not _interpreter_readable_by_others():
        pytest.skip("the interpreter or the kit lies where user nobody cannot read it")

    def attempt():
        sandbox._SERVER = sandbox._ForkServer()  # this child's own fork server, as nobody
        try:
            return _try_escape(kind, str(outside))
        finally:
            sandbox._SERVER.close()

    ok, got = run_unprivileged(attempt, timeout=120)
    assert ok, got
    assert os.listdir(outside) == [], got


def test_no_shell_through_fork_exec(outside):
    """``_posixsubprocess.fork_exec`` (no ctypes, no subprocess audit event) runs no shell:
    exec is refused, the hidden cases reach neither a file outside nor the feedback."""
    defs = f'''
def f():
    import _posixsubprocess
    r, w = os.pipe()
    er, ew = os.pipe()
    cmd = "cat {CASES}; cat {CASES} > {outside}/leak"
    pid = _posixsubprocess.fork_exec([b"/bin/sh", b"-c", cmd.encode()], [b"/bin/sh"], True, (w, ew), None,
                                     None, -1, -1, -1, w, -1, -1, er, ew, True, False, -1, None, None, None,
                                     -1, None, False)
    os.close(w)
    os.close(ew)
    err = os.read(er, 1000)
    got = b""
    while chunk := os.read(r, 65536):
        got += chunk
    os.waitpid(pid, 0)
    print(got.decode(errors="replace"), err)
    return float(len(got))
'''
    run = _run(defs)
    c = run.checks[0].calls[0]
    assert SECRET not in c.stdout and SECRET not in c.error
    assert not (outside / "leak").exists()
    assert not c.ok or float(c.value) == 0.0, c


def test_hidden_cases_not_readable():
    run = _run(f"def f():\n    return float(len(open({str(CASES)!r}).read()))\n")
    assert not run.checks[0].calls[0].ok


def test_forged_answers_while_loading_are_ignored():
    """Load-time code writes forged events on every descriptor and a forged answer file: the
    control pipe is not among its descriptors, the answers must carry the check's token."""
    defs = '''
def forge():
    msgs = b'{"event": "start", "id": 0, "nonce": "x"}\\n{"event": "done", "id": 0, "status": "exit 0"}\\n' \\
        + b'{"event": "finished"}\\n'
    for fd in range(3, 256):
        try:
            os.write(fd, msgs)
        except OSError:
            pass
    import json
    import numpy as np
    np.save(".answers/forged.npy", np.array(42.0))
    json.dump({"nonce": "x", "calls": [{"ok": True, "value": {"kind": "array", "file": "forged.npy"}}]},
              open(".answers/check_0.json", "w"))
    return 0


def f(_=forge()):
    return 7.0
'''
    run = _run(defs)
    assert float(_value(run)) == 7.0


MARKER_CHILD = '''
def f():
    started = 0
    for _ in range({n}):
        try:
            pid = os.fork()
        except OSError:  # the process limit (64 under root's fresh uid) is a barrier too
            break
        started += 1
        if pid == 0:
            os.setsid()
            keep = open({marker!r})
            while True:
                time.sleep(1)
    return float(started > 10)
'''


def _holders(marker: Path) -> list[int]:
    """Processes that hold ``marker`` open."""
    found = []
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            for fd in os.listdir(f"/proc/{d}/fd"):
                if os.readlink(f"/proc/{d}/fd/{fd}") == str(marker):
                    found.append(int(d))
                    break
        except OSError:
            continue
    return found


def test_no_process_outlives_its_check(outside):
    """A check that starts 80 processes (each in its own session, holding a marker file open):
    none is left once grading returns."""
    marker = outside / "marker"
    marker.write_text("x")
    os.chmod(marker, 0o644)
    run = _run(MARKER_CHILD.format(n=80, marker=str(marker)), calls=(("f", ()), ("f", ())))
    assert float(_value(run, 0)) == 1.0 and float(_value(run, 1)) == 1.0
    assert _holders(marker) == []
    assert run.notes["survivors"] == 0


@pytest.mark.parametrize("without", [("namespaces",), ("namespaces", "landlock")])
def test_no_process_outlives_without_namespaces(outside, monkeypatch, without):
    """The fallbacks of a machine without PID namespaces (and without Landlock): the check's
    process group, then the grader's look for the submission's session and uid."""
    monkeypatch.setattr(sandbox, "WITHOUT", set(without))
    marker = outside / "marker"
    marker.write_text("x")
    os.chmod(marker, 0o644)
    run = _run(MARKER_CHILD.format(n=20, marker=str(marker)))
    assert float(_value(run, 0)) == 1.0
    assert not run.notes["pid_namespace"]
    assert _holders(marker) == []
    assert run.notes["survivors"] == 0


def test_side_by_side_submissions_cannot_kill_each_other():
    """With two submissions graded at once, one calling ``kill(-1, SIGKILL)`` over and over,
    the other still gets its answer."""
    killer = "def f():\n    for _ in range(300):\n        try:\n            os.kill(-1, signal.SIGKILL)\n" \
             "        except OSError:\n            pass\n        time.sleep(0.01)\n    return 0.0\n"
    victim = "def f():\n    for _ in range(100):\n        time.sleep(0.01)\n    return 5.0\n"
    out = {}

    def grade(name, defs):
        out[name] = _run(defs, calls=(("f", ()), ("f", ()), ("f", ())))

    threads = [threading.Thread(target=grade, args=a) for a in (("killer", killer), ("victim", victim))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert [float(_value(out["victim"], i)) for i in range(3)] == [5.0, 5.0, 5.0]
    if os.geteuid() == 0:
        assert out["killer"].notes["uid"] != out["victim"].notes["uid"]


def test_cpu_limit_apart_from_wall_limit():
    """A check burning CPU with a generous wall limit is stopped for CPU; one sleeping past the
    wall limit with an idle CPU is stopped for time. The reason is asserted, not the time."""
    defs = "def burn():\n    while True:\n        pass\n\ndef nap():\n    time.sleep(10 ** 6)\n"
    burn = sandbox.run_calls([("import time", 1), (defs, 2)],
                             [{"id": 0, "calls": [("burn", ())], "wall": 120.0, "cpu": 1}])
    assert "CPU time" in burn.checks[0].failure and "time limit" not in burn.checks[0].failure
    nap = sandbox.run_calls([("import time", 1), (defs, 2)],
                            [{"id": 0, "calls": [("nap", ())], "wall": 1.0, "cpu": 60}])
    assert "time limit" in nap.checks[0].failure and "CPU" not in nap.checks[0].failure


@pytest.fixture(scope="module")
def material():
    m = Material.load(ROOT)
    m.checks("02_homography")
    return m


SOLVER = "np.asarray(SOLVE(np.asarray(src, float), np.asarray(dst, float))[0], float)"
ROUTES = {  # how estimate_homography reaches OpenCV's solver without naming it in the code
    "importlib": ("import importlib", "importlib.import_module('c' + 'v2').__getattribute__('find' + 'Homography')"),
    "sys_modules": ("", "getattr(sys.modules['c' + 'v2'], 'find' + 'Homography')"),
    "vars": ("", "vars(sys.modules['c' + 'v2'])['find' + 'Homography']"),
    "dict": ("", "sys.modules['c' + 'v2'].__dict__['find' + 'Homography']"),
    "eval": ("", "eval('__imp' + 'ort__(\"cv2\").findHomo' + 'graphy')"),
    "builtins_import": ("import builtins", "getattr(builtins.__import__('c' + 'v2'), 'find' + 'Homography')"),
    "globals": ("", "globals().setdefault('_s', getattr(__builtins__['__import__']('c' + 'v2') if isinstance("
                    "__builtins__, dict) else __builtins__.__import__('c' + 'v2'), 'find' + 'Homography'))"),
}


@pytest.mark.parametrize("route", list(ROUTES))
def test_solver_caught_at_run_time(tmp_path, material, route):
    head, expr = ROUTES[route]
    src = f"""import sys
import numpy as np
{head}


def apply_homography(H, pts):
    p = np.column_stack([pts, np.ones(len(pts))]) @ np.asarray(H, dtype=float).T
    return p[:, :2] / p[:, 2:3]


def estimate_homography(src, dst):
    SOLVE = {expr}
    H = {SOLVER}
    return H / H[2, 2]
"""
    p = tmp_path / "02_homography.py"
    p.write_text(src)
    res = grade_file(p, material, "02_homography")
    apply_, estimate = res.functions
    report = text(res)
    assert apply_.score == apply_.max_score, report
    assert estimate.score == 0 and estimate.status == "academic honesty", report
    assert "cv2.findHomography" in report, report


def test_kit_solver_caught_at_run_time(tmp_path, material):
    src = """import numpy as np
import importlib


def estimate_homography(src, dst):
    m = importlib.import_module('dtscal_lib.' + 'homography')
    return m.estimate_homography(src, dst)
"""
    p = tmp_path / "02_homography.py"
    p.write_text(src)
    res = grade_file(p, material, "02_homography")
    estimate = res.functions[1]
    assert estimate.score == 0 and estimate.status == "academic honesty", text(res)
    assert "dtscal_lib.homography.estimate_homography" in text(res)


def test_huge_submission_is_not_parsed(tmp_path, material):
    """A 16 MB .py of one expression is refused before parsing (it once took 3.4 GB)."""
    p = tmp_path / "02_homography.py"
    with open(p, "w") as f:
        f.write("x = (" + "1 + " * (4 * 2 ** 20) + "1)\n")
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    res = grade_file(p, material, "02_homography")
    grown_mb = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024
    assert res.score == 0 and any("more than" in n for n in res.notes), res.notes
    assert grown_mb < 100, grown_mb


def test_barriers_hold_for_an_unprivileged_grader(outside):
    """The grader run by an ordinary user (here: this interpreter, forked, as ``nobody``): the
    supervisor's namespaces and the loader's lock-in still refuse a write outside through a
    folder descriptor and refuse to run a shell, and the loader is init of its own PID namespace."""
    from dtscal_lib.grading import barriers, child

    if not barriers.landlock_abi():
        pytest.skip("this kernel has no Landlock")  # then the uid and the audit hook are the barriers
    work = Path(tempfile.mkdtemp(prefix="dtscal-work-"))
    os.chmod(work, 0o777)

    def attempt():
        notes = child._namespaces({"blocked_paths": [str(ROOT / "grading")]})
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:
            got = [f"pid {os.getpid()}"]
            try:
                child._lock_in({"workdir": str(work), "outdir": str(work), "mem_mb": 4096, "uid": None,
                                "blocked_paths": [str(ROOT / "grading"), str(ROOT / "solutions")]})
                fd = os.open(str(outside), os.O_RDONLY)
                for name, act in (("create", lambda: os.close(os.open("x", os.O_WRONLY | os.O_CREAT, dir_fd=fd))),
                                  ("exec", lambda: os.execv("/bin/sh", ["sh", "-c", f"touch {outside}/y"])),
                                  ("read", lambda: open(CASES).read())):
                    try:
                        act()
                        got.append(f"{name} allowed")
                    except OSError:
                        got.append(f"{name} refused")
                open("inside", "w").write("ok")
            except BaseException as exc:  # noqa: BLE001
                got.append(repr(exc))
            os.write(w, " ".join(got).encode())
            os._exit(0)
        os.close(w)
        text = os.read(r, 10000).decode()
        os.waitpid(pid, 0)
        return f"{notes.get('pid_namespace')} {text}"

    try:
        ok, got = run_unprivileged(attempt, timeout=60)
        assert ok, got
        assert "create refused" in got and "exec refused" in got and "read refused" in got, got
        assert os.listdir(outside) == [] and (work / "inside").is_file(), got
        if got.startswith("True"):
            assert "pid 1 " in got, got
    finally:
        shutil.rmtree(work, ignore_errors=True)
