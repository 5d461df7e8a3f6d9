"""Escapes from the grading sandbox, each tried for real: the test fails if a file outside appears,
a secret reaches the answer, a process survives, another submission is hurt or a borrowed solver
gets credit. ``docs/grading-sandbox.md`` lists each route with the barrier that stops it.

The routes run as the grader's user (root in CI) and, through :func:`unprivileged.run_unprivileged`
with an interpreter ``nobody`` can read (:mod:`sandbox_user`), as an ordinary user: none skips.
Where bubblewrap is missing, CI fails (tests/ci.py) instead of skipping.
"""

from __future__ import annotations

import io
import json
import os
import resource
import shutil
import socket
import struct
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import numpy as np
import pytest

from ci import missing
from dtscal_lib.grading import sandbox
from dtscal_lib.grading.classroom import Item, grade_all
from dtscal_lib.grading.grade import grade_file
from dtscal_lib.grading.material import Material
from dtscal_lib.grading.report import text
from nbtools import ROOT
from sandbox_user import readable_python, use
from unprivileged import run_unprivileged, shared_tmp

CASES = ROOT / "grading" / "cases.py"
SECRET = "POINTS_PER_FUNCTION"  # a word of the hidden cases file


@pytest.fixture(scope="module", autouse=True)
def bubblewrap():
    ok, why = sandbox.bwrap_available()
    if not ok:
        missing(f"bubblewrap does not run here ({why}); scripts/install-sandbox.sh installs it")


@pytest.fixture()
def outside():
    """A folder outside the sandbox that everyone may write (so only the sandbox stops a write)."""
    d = Path(tempfile.mkdtemp(prefix="dtscal-outside-"))
    os.chmod(d, 0o777)
    yield d
    shutil.rmtree(d, ignore_errors=True)


def _run(defs: str, wall=10.0, cpu=5, calls=(("f", ()),), mem_mb=sandbox.MEM_MB):
    statements = [("import os\nimport sys\nimport time\nimport signal", 1), (defs, 5)]
    checks = [sandbox.CheckJob(id=i, calls=[c], wall=wall, cpu=cpu) for i, c in enumerate(calls)]
    return sandbox.run_calls(statements, checks, mem_mb=mem_mb)


def _value(run, cid=0):
    cr = run.checks[cid]
    assert not cr.failure, cr.failure
    c = cr.calls[0]
    return c.value if c.ok else c.error


def _said(run, cid=0) -> str:
    c = run.checks[cid].calls[0]
    return f"{c.value if c.ok else c.error} {c.stdout}"


ESCAPES = {
    "open": "open(OUT + '/escaped', 'w').write('x')",
    "rename": "open('a', 'w').write('x')\n    os.rename('a', OUT + '/escaped')",
    "symlink": "os.symlink('/etc/hostname', OUT + '/escaped')",
    "link": "open('a', 'w').write('x')\n    os.link('a', OUT + '/escaped')",
    "open_dir_fd": "fd = os.open(OUT, os.O_RDONLY)\n"
                   "    os.close(os.open('escaped', os.O_WRONLY | os.O_CREAT, 0o644, dir_fd=fd))",
    "mkdir_dir_fd": "fd = os.open(OUT, os.O_RDONLY)\n    os.mkdir('escaped', dir_fd=fd)",
}


def _try_escape(kind: str, out: str) -> str:
    return str(_value(_run(f"OUT = {out!r}\n\ndef f():\n    {ESCAPES[kind]}\n    return 1.0\n")))


@pytest.mark.parametrize("kind", list(ESCAPES))
def test_no_file_outside_the_working_folder(kind, outside):
    got = _try_escape(kind, str(outside))
    assert os.listdir(outside) == [], got
    assert "Error" in got, got  # refused, and the student is told


@pytest.fixture(scope="module")
def user_python():
    with shared_tmp() as d:
        yield readable_python(d)


def _as_user(user_python, fn, *args):
    def attempt():
        use(*user_python)
        return fn(*args)

    ok, got = run_unprivileged(attempt, timeout=180)
    assert ok, got
    return got


def test_barriers_hold_for_an_unprivileged_grader(outside, user_python):
    """The grader run as ``nobody``: bubblewrap runs (user namespaces), nothing is written outside,
    the hidden cases are absent, exec is refused."""
    def attempt():
        body = (f"def f():\n    out = []\n    try:\n        open({str(outside)!r} + '/x', 'w')\n"
                "        out.append('write allowed')\n    except OSError as e:\n        out.append('write refused')\n"
                f"    try:\n        open({str(CASES)!r}).read()\n        out.append('read allowed')\n"
                "    except OSError:\n        out.append('read refused')\n"
                "    try:\n        os.execv('/usr/bin/true', ['true'])\n    except OSError:\n"
                "        out.append('exec refused')\n    print(' '.join(out))\n    return 1.0\n")
        run = _run(body)
        return f"{run.notes['mode']} {_said(run)}"

    got = _as_user(user_python, attempt)
    assert got.startswith("bubblewrap"), got
    assert "write refused" in got and "read refused" in got and "exec refused" in got, got
    assert os.listdir(outside) == [], got


USER_ROUTES = {  # as an ordinary user: each body prints ESCAPED when it gets through
    "memfd": "fd = os.memfd_create('x')\n    print('ESCAPED')",
    "socket": "import socket\n    socket.socket(socket.AF_UNIX).connect('/run/docker.sock')\n    print('ESCAPED')",
    "proc": "print('ESCAPED' if len([p for p in os.listdir('/proc') if p.isdigit()]) > 4 else 'own proc only')",
    "kit": f"print(os.listdir({str(ROOT)!r}))\n    print('ESCAPED')",
    "fork": "os.fork()\n    print('ESCAPED')",
    "cv2": "import cv2\n    cv2.findHomography\n    print('ESCAPED')",
}


@pytest.mark.parametrize("route", list(USER_ROUTES))
def test_routes_as_unprivileged_user(user_python, route):
    body = f"def f():\n    {USER_ROUTES[route]}\n    return 1.0\n"
    got = _as_user(user_python, lambda: _said(_run(body)))
    assert "ESCAPED" not in got, got
    assert "Error" in got or "own proc only" in got, got


def test_users_secret_key_not_readable(user_python):
    """As an ordinary user: a private key readable by the grader's user (its ``~/.ssh/id_rsa``) is
    not in the sandbox's files."""
    with shared_tmp() as home:
        key = home / ".ssh" / "id_rsa"
        key.parent.mkdir()
        key.write_text("-----BEGIN OPENSSH PRIVATE KEY----- secret")
        os.chmod(key.parent, 0o755)
        os.chmod(key, 0o644)
        body = f"def f():\n    print(open({str(key)!r}).read())\n    return 1.0\n"
        got = _as_user(user_python, lambda: _said(_run(body)))
        assert "secret" not in got and "No such file" in got, got
        got = _said(_run(body))  # and as the grader's own user (root in CI)
        assert "secret" not in got and "No such file" in got, got


def test_etc_shadow_and_home_not_readable():
    body = ("def f():\n    out = []\n    for p in ('/etc/shadow', '/etc/passwd', os.path.expanduser('~root') + "
            f"'/.ssh/id_rsa', {str(Path.home() / '.ssh' / 'id_rsa')!r}):\n"
            "        try:\n            out.append(open(p).read()[:20])\n        except OSError as e:\n"
            "            out.append(type(e).__name__)\n    print(out)\n    return 1.0\n")
    got = _said(_run(body))
    assert got.count("FileNotFoundError") == 4, got


def test_no_shell_through_fork_exec(outside):
    """``_posixsubprocess.fork_exec`` runs no shell: no process may start, exec is refused, and
    there is no shell in the sandbox to run."""
    defs = f'''
def f():
    import _posixsubprocess
    r, w = os.pipe()
    er, ew = os.pipe()
    cmd = "cat {CASES}; cat {CASES} > {outside}/leak"
    pid = _posixsubprocess.fork_exec([b"/bin/sh", b"-c", cmd.encode()], [b"/bin/sh"], True, (w, ew), None,
                                     None, -1, -1, -1, w, -1, -1, er, ew, True, False, -1, None, None, None,
                                     -1, None, False)
    return float(pid)
'''
    c = _run(defs).checks[0].calls[0]
    assert SECRET not in c.stdout and SECRET not in c.error
    assert not (outside / "leak").exists()
    assert not c.ok and "Operation not permitted" in c.error, c


def test_memfd_exec_refused():
    """An ELF written to a memfd (or to the working folder) does not run."""
    defs = '''
def f():
    out = []
    try:
        fd = os.memfd_create("x")
        out.append("memfd allowed")
    except OSError as e:
        out.append("memfd refused")
    elf = open(sys.executable, "rb").read()
    open("prog", "wb").write(elf)
    os.chmod("prog", 0o755)
    try:
        os.execv("./prog", ["prog", "-c", "pass"])
    except OSError:
        out.append("exec refused")
    print(" ".join(out))
    return 1.0
'''
    got = _said(_run(defs))
    assert "memfd refused" in got and "exec refused" in got, got


def test_host_unix_socket_unreachable(outside):
    """A root-owned 0777 pathname socket of the host (a container daemon's, say) answers no one."""
    path = outside / "daemon.sock"
    srv = socket.socket(socket.AF_UNIX)
    srv.bind(str(path))
    os.chmod(path, 0o777)
    srv.listen(1)
    srv.settimeout(0.5)
    try:
        body = (f"def f():\n    import socket\n    s = socket.socket(socket.AF_UNIX)\n    s.connect({str(path)!r})\n"
                "    s.send(b'GET /secrets')\n    return 1.0\n")
        got = _said(_run(body))
        with pytest.raises(OSError):
            srv.accept()
    finally:
        srv.close()
    assert "Error" in got, got


def test_no_network_interface():
    """The network namespace: no interface but loopback (read from /proc, no socket needed)."""
    body = "def f():\n    print(open('/proc/net/dev').read())\n    return 1.0\n"
    lines = _said(_run(body)).split("\n")[2:]
    names = [ln.split(":")[0].strip() for ln in lines if ":" in ln]
    assert names == ["lo"], lines


def test_host_proc_not_visible():
    """The sandbox's /proc is its own PID namespace's: a handful of processes, none of the host's."""
    body = ("def f():\n    pids = [int(p) for p in os.listdir('/proc') if p.isdigit()]\n"
            "    cmd = [open(f'/proc/{p}/cmdline', 'rb').read().replace(b'\\0', b' ')[:60] for p in pids]\n"
            "    print(cmd)\n    return float(len(pids))\n")
    run = _run(body)
    assert float(_value(run)) <= 4, _said(run)
    assert "pytest" not in _said(run)


def test_classmate_file_not_reachable_through_proc(tmp_path):
    """Two submissions graded at once: the copier looks through /proc/*/cmdline and /proc/*/environ
    for the other one's file and tries to read it; it finds neither."""
    alice = tmp_path / "alice.py"
    alice.write_text("MARK = 'alice-solution'\n")
    os.chmod(tmp_path, 0o755)
    slow = "def f():\n    time.sleep(1.5)\n    return 5.0\n"
    copier = ("def f():\n    seen = []\n    for p in os.listdir('/proc'):\n        if p.isdigit():\n"
              "            for k in ('cmdline', 'environ'):\n                try:\n"
              "                    seen.append(open(f'/proc/{p}/{k}', 'rb').read())\n"
              "                except OSError:\n                    pass\n"
              "    print(b'alice' in b''.join(seen))\n"
              f"    try:\n        print(open({str(alice)!r}).read())\n    except OSError as e:\n"
              "        print(type(e).__name__)\n    return 1.0\n")
    out = {}

    def grade(name, defs):
        out[name] = _run(defs)

    threads = [threading.Thread(target=grade, args=a) for a in (("alice", slow), ("copier", copier))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    said = _said(out["copier"])
    assert "False" in said and "FileNotFoundError" in said and "alice-solution" not in said, said
    assert float(_value(out["alice"])) == 5.0


def test_git_objects_not_readable():
    """The kit's .git (and the common .git of a worktree), whose packs hold the hidden cases' history."""
    common = subprocess.run(["git", "rev-parse", "--git-common-dir"], cwd=ROOT, capture_output=True, text=True)
    places = [str(ROOT / ".git"), str(ROOT)]
    if common.returncode == 0:
        places.append(str((ROOT / common.stdout.strip()).resolve() / "objects" / "pack"))
    body = (f"def f():\n    out = []\n    for p in {places!r}:\n        try:\n            out.append(os.listdir(p))\n"
            "        except OSError as e:\n            out.append(type(e).__name__)\n    print(out)\n    return 1.0\n")
    got = _said(_run(body))
    assert got.count("FileNotFoundError") == len(places), got


def test_forged_answers_are_ignored():
    """Student code writes forged answer frames (value 42 for every check) on every descriptor it
    has and tries the harness's (its parent's) descriptors and memory through /proc. The grader's
    channel is not among them: no 42 is taken. (Its own answer pipe is: bytes written there
    spoil that check's own answer, which then counts as a process that ended; a well-formed frame
    there is only another way to return values, judged like any.)"""
    defs = '''
def forge():
    import json, struct, io
    import numpy as np
    buf = io.BytesIO()
    np.save(buf, np.array(42.0))
    blob = buf.getvalue()
    calls = [{"ok": True, "value": {"kind": "array", "blob": 0}}]
    inner = json.dumps({"calls": calls, "blobs": [len(blob)]}).encode()
    answer = struct.pack(">I", len(inner)) + inner + blob
    msgs = b""
    for i in range(3):
        head = json.dumps({"event": "check", "id": i, "status": "exit 0", "blobs": [len(answer)]}).encode()
        msgs += struct.pack(">I", len(head)) + head + answer
    head = json.dumps({"event": "finished", "blobs": []}).encode()
    msgs += struct.pack(">I", len(head)) + head
    for fd in range(0, 256):
        try:
            os.write(fd, msgs)
        except OSError:
            pass
    for p in (f"/proc/{os.getppid()}/fd/{i}" for i in range(64)):
        try:
            with open(p, "wb") as f:
                f.write(msgs)
            print("wrote", p)
        except OSError:
            pass
    try:
        open(f"/proc/{os.getppid()}/mem", "rb")
        print("parent memory open")
    except OSError:
        pass
    return 0


def f(_=forge()):
    forge()
    return 7.0
'''
    run = _run(defs, calls=(("f", ()), ("f", ()), ("f", ())))
    for i in range(3):
        cr = run.checks[i]
        assert cr.failure or float(cr.calls[0].value) == 7.0, cr
        assert cr.failure.startswith("the function ended the process") or not cr.failure, cr
    clean = _run(defs.replace("    forge()\n    return 7.0", "    return 7.0"), calls=(("f", ()), ("f", ())))
    assert [float(_value(clean, i)) for i in range(2)] == [7.0, 7.0]  # forged while loading: nothing
    said = " ".join(c.stdout for cr in run.checks.values() for c in cr.calls)
    assert "wrote" not in said and "parent memory open" not in said, said


def _refs(n: int, blob: bytes) -> bytes:
    calls = [{"ok": True, "value": {"kind": "array", "blob": 0}} for _ in range(n)]
    head = json.dumps({"calls": calls, "blobs": [len(blob)]}).encode()
    return struct.pack(">I", len(head)) + head + blob


def test_one_array_referenced_2000_times_is_decoded_once():
    """A worker's frame referring 2000 times to one 1 MiB array is refused (more calls than any
    check has); 900 times, the array is decoded once and the other 899 answers are unreadable."""
    buf = io.BytesIO()
    np.save(buf, np.zeros(2 ** 17))
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    assert sandbox.decode_answers(_refs(2000, buf.getvalue())) is None
    got = sandbox.decode_answers(_refs(900, buf.getvalue()))
    grown_mb = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024
    assert sum(isinstance(c.value, np.ndarray) for c in got) == 1
    assert grown_mb < 50, grown_mb


def test_oversized_answer_frame_is_refused():
    head = json.dumps({"calls": [], "blobs": [2 ** 40]}).encode()
    assert sandbox.decode_answers(struct.pack(">I", len(head)) + head) is None
    assert sandbox.decode_answers(struct.pack(">I", 2 ** 31) + b"{}") is None


FORKER = '''
def f():
    started, errors = 0, set()
    for _ in range({n}):
        try:
            pid = os.fork()
        except OSError as e:
            errors.add(e.strerror)
            continue
        started += 1
        if pid == 0:
            blocks = [bytearray(300 * 2 ** 20)]
            time.sleep(100)
    print(started, errors)
    return float(started)
'''


def test_fork_bomb_and_memory_of_many_processes():
    """200 forks (each to hold 300 MB): none starts, so the submission's memory is that of one process."""
    run = _run(FORKER.format(n=200))
    assert float(_value(run)) == 0.0, _said(run)
    assert "Operation not permitted" in _said(run)
    assert run.notes["survivors"] == 0


def test_memory_cap_is_per_submission():
    """One process asking for more than --mem gets a MemoryError; threads cannot multiply it."""
    body = ("def f():\n    import threading\n    out = []\n    try:\n        b = bytearray(1100 * 2 ** 20)\n"
            "        out.append('allocated')\n    except MemoryError:\n        out.append('MemoryError')\n"
            "    try:\n        threading.Thread(target=print).start()\n        out.append('thread')\n"
            "    except RuntimeError:\n        out.append('no thread')\n    print(out)\n    return 1.0\n")
    got = _said(_run(body, mem_mb=1024))
    assert "MemoryError" in got and "no thread" in got, got


def test_side_by_side_submissions_cannot_kill_each_other():
    killer = ("def f():\n    for _ in range(100):\n        for p in range(1, 200):\n            try:\n"
              "                os.kill(p, signal.SIGKILL) if p != os.getpid() else None\n"
              "            except OSError:\n                pass\n        time.sleep(0.01)\n    return 0.0\n")
    victim = "def f():\n    for _ in range(100):\n        time.sleep(0.01)\n    return 5.0\n"
    out = {}

    def grade(name, defs):
        out[name] = _run(defs, calls=(("f", ()), ("f", ())))

    threads = [threading.Thread(target=grade, args=a) for a in (("killer", killer), ("victim", victim))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert [float(_value(out["victim"], i)) for i in range(2)] == [5.0, 5.0]
    assert float(_value(out["killer"], 0)) == 0.0  # the killer's own harness survived it too
    assert out["killer"].notes["uid"] != out["victim"].notes["uid"]


def test_two_graders_at_once_use_different_uids():
    """A second grader (another process) holding uid slot 0: this one's sandbox takes another uid."""
    code = ("import sys, time; sys.path.insert(0, %r); from dtscal_lib.grading import sandbox; k, fd = "
            "sandbox._SLOTS.take(); print(sandbox.SANDBOX_UID_BASE + k, flush=True); time.sleep(30)" % str(ROOT))
    other = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        their_uid = int(other.stdout.readline())
        run = _run("def f():\n    return float(os.getuid())\n")
        assert run.notes["uid"] != their_uid
        assert float(_value(run)) == run.notes["uid"]
    finally:
        other.kill()
        other.wait()


def test_cpu_limit_apart_from_wall_limit():
    defs = "def burn():\n    while True:\n        pass\n\ndef nap():\n    time.sleep(10 ** 6)\n"
    burn = sandbox.run_calls([("import time", 1), (defs, 2)],
                             [sandbox.CheckJob(id=0, calls=[("burn", ())], wall=120.0, cpu=1)])
    assert "CPU time" in burn.checks[0].failure and "time limit" not in burn.checks[0].failure
    nap = sandbox.run_calls([("import time", 1), (defs, 2)],
                            [sandbox.CheckJob(id=0, calls=[("nap", ())], wall=1.0, cpu=60)])
    assert "time limit" in nap.checks[0].failure and "CPU" not in nap.checks[0].failure


@pytest.fixture(scope="module")
def material():
    m = Material.load(ROOT)
    m.checks("02_homography")
    return m


APPLY = '''

def apply_homography(H, pts):
    p = np.column_stack([pts, np.ones(len(pts))]) @ np.asarray(H, dtype=float).T
    return p[:, :2] / p[:, 2:3]
'''

SOLVER = "np.asarray(SOLVE(np.asarray(src, float), np.asarray(dst, float))[0], float)"
ROUTES = {  # how estimate_homography reaches OpenCV's solver without naming it in the code
    "native": ("import cv2", "getattr(getattr(cv2, '_nat' + 'ive'), 'find' + 'Homography')"),
    "importlib": ("import importlib", "importlib.import_module('c' + 'v2').__getattribute__('find' + 'Homography')"),
    "sys_modules": ("import cv2", "getattr(sys.modules['c' + 'v2'], 'find' + 'Homography')"),
    "vars": ("import cv2", "vars(sys.modules['c' + 'v2'])['find' + 'Homography']"),
    "eval": ("", "eval('__imp' + 'ort__(\"cv2\").findHomo' + 'graphy')"),
    "file_loader": ("import importlib.util", "importlib.util.module_from_spec(importlib.util.spec_from_file_location("
                                             "'c', __import__('glob').glob('/**/cv2*.so', recursive=True)[0]))"),
}


@pytest.mark.parametrize("route", list(ROUTES))
def test_borrowed_solver_gets_no_credit(tmp_path, material, route):
    head, expr = ROUTES[route]
    src = f"import sys\nimport numpy as np\n{head}\n{APPLY}\n\ndef estimate_homography(src, dst):\n" \
          f"    SOLVE = {expr}\n    H = {SOLVER}\n    return H / H[2, 2]\n"
    p = tmp_path / "02_homography.py"
    p.write_text(src)
    res = grade_file(p, material, "02_homography")
    apply_, estimate = res.functions
    assert apply_.score == apply_.max_score, text(res)
    assert estimate.score == 0, text(res)


def test_kit_under_another_package_name(tmp_path, material):
    """A module whose ``__path__`` is the kit's folder: the folder is not in the sandbox."""
    src = f"""import sys
import types
import importlib
import numpy as np
{APPLY}

def estimate_homography(src, dst):
    m = types.ModuleType("mykit")
    m.__path__ = [{str(ROOT / 'dtscal_lib')!r}]
    sys.modules["mykit"] = m
    return importlib.import_module("mykit.homography").estimate_homography(src, dst)
"""
    p = tmp_path / "02_homography.py"
    p.write_text(src)
    res = grade_file(p, material, "02_homography")
    assert res.functions[1].score == 0 and "No module named 'mykit.homography'" in text(res), text(res)


def test_kit_solver_import_names_the_rule(tmp_path, material):
    src = "import numpy as np\nimport importlib\n" + APPLY + \
          "\n\ndef estimate_homography(src, dst):\n    m = importlib.import_module('dtscal_lib.' + 'homography')\n" \
          "    return m.estimate_homography(src, dst)\n"
    p = tmp_path / "02_homography.py"
    p.write_text(src)
    res = grade_file(p, material, "02_homography")
    estimate = res.functions[1]
    assert estimate.score == 0 and estimate.status == "academic honesty", text(res)
    assert "dtscal_lib.homography" in text(res)


CORRECT = (ROOT / "solutions" / "02_homography.ipynb")
FILLER = '''import os
import numpy as np


def apply_homography(H, pts):
    k = 0
    while True:
        try:
            with open(f"fill{k}", "wb") as f:
                f.write(b"x" * 2 ** 24)
            with open(f"/tmp/more{k}", "wb") as f:
                f.write(b"x" * 2 ** 24)
        except OSError:
            break
        k += 1
    return np.zeros((len(pts), 2))


def estimate_homography(src, dst):
    return np.eye(3)
'''


def test_disk_filler_hurts_no_classmate(tmp_path, material):
    """--jobs 2: one submission fills its disk on every check; three correct classmates keep full marks."""
    filler = tmp_path / "filler" / "02_homography.py"
    filler.parent.mkdir()
    filler.write_text(FILLER)
    items = [Item("filler", filler, "02_homography")]
    for s in ("ann", "ben", "cai"):
        d = tmp_path / s
        d.mkdir()
        shutil.copy(CORRECT, d / "02_homography.ipynb")
        items.append(Item(s, d / "02_homography.ipynb", "02_homography"))
    results = grade_all(items, material, jobs=2)
    for res in results[1:]:
        assert res.score == res.max_score, text(res)


def test_grader_failure_is_retried_then_not_charged(tmp_path, material, monkeypatch):
    """A sandbox that fails to start once is started again; one that never starts gives
    'not graded: grader error, rerun', never a zero charged to the student."""
    p = tmp_path / "02_homography.ipynb"
    shutil.copy(CORRECT, p)
    real = sandbox.bwrap_argv
    failures = {"left": 1}

    def flaky(*a, **k):
        if failures["left"]:
            failures["left"] -= 1
            return ["false"]
        return real(*a, **k)

    monkeypatch.setattr(sandbox, "bwrap_argv", flaky)
    res = grade_file(p, material, "02_homography")
    assert res.score == res.max_score, text(res)
    failures["left"] = 10 ** 6
    res = grade_file(p, material, "02_homography")
    for f in res.functions:
        assert f.score == 0 and all(sandbox.GRADER_ERROR in t.output for t in f.tests), text(res)
    assert all(f.status != "graded" for f in res.functions), text(res)
    assert any(n.startswith(sandbox.GRADER_ERROR) for n in res.notes), res.notes


def test_without_bubblewrap_the_grader_refuses_unless_the_risk_is_accepted(tmp_path, monkeypatch, capsys):
    """Without bubblewrap `dtscal grade` refuses, says why (the preflight) and names the option; with
    the option it grades, and the barrier report states only what holds."""
    from dtscal_lib.cli import main as dtscal
    from dtscal_lib.grading.command import UNCONFINED

    monkeypatch.setattr(sandbox, "MODE", "bare")
    p = tmp_path / "02_homography.ipynb"
    shutil.copy(CORRECT, p)
    out = tmp_path / "results.json"
    assert dtscal(["grade", str(p), "--json", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert "not grading: bubblewrap cannot run here" in err and UNCONFINED in err and "Fix:" in err, err
    assert not out.exists()
    assert dtscal(["grade", str(p), "--json", str(out), "-q", UNCONFINED]) == 0
    data = json.loads(out.read_text())
    held = data["sandbox"]
    assert held["mode"] == "bare" and "filesystem" not in held and "user" not in held
    assert any(n.startswith("filesystem") for n in held["not_held"]) and "PID namespace" in held["not_held"]
    assert "signals only to itself" in held["processes"] and "sockets refused" in held["network"]
    assert data["score"] == 20
    assert "sandbox: bare -- NOT held: filesystem" in capsys.readouterr().err
    run = _run("def f():\n    os.execv('/bin/true', ['true'])\n")  # seccomp holds without bubblewrap
    assert "Operation not permitted" in _said(run)
