"""The trusted side of the sandbox: start the child, enforce deadlines, read its answers.

:func:`run_calls` hands the submission's statements and the checks' inputs (never the
expected answers) to :mod:`dtscal_lib.grading.child`, watches its control pipe, kills it
when a deadline passes, starts it again without the statement or past the check that
killed it, and reads the answers back as plain ``.npy`` arrays (``allow_pickle=False``):
nothing the student's process writes can run code in the grader.
"""

from __future__ import annotations

import atexit
import json
import os
import pickle
import select
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .jobs import as_wire

#: default limits, per check (wall-clock and CPU seconds) and per process (memory)
WALL_S, CPU_S, MEM_MB, OUTPUT_CHARS = 10.0, 8, 2048, 2000
#: bounds of the limits an instructor may set (``dtscal grade --wall/--cpu/--mem``):
#: the reference solutions' slowest check takes well under 1 s, so 600 s per check is already
#: generous; the preloaded grading process maps 444 MB of address space (VmPeak, numpy +
#: OpenCV + the kit, measured) before a submission allocates anything: 1024 MB leaves room
#: for the 640x480 float maps of notebook 04.
MAX_WALL_S, MAX_CPU_S, MIN_MEM_MB = 600.0, 600, 1024


def validate_limits(wall_s, cpu_s, mem_mb) -> None:
    """Refuse limits that make no sense (NaN, negative, astronomically large), with why."""
    import math

    from ..errors import DtscalError

    try:
        wall = float(wall_s)
    except (TypeError, ValueError):
        raise DtscalError(f"--wall {wall_s!r}: give the seconds per check as a number") from None
    if not math.isfinite(wall) or not 0 < wall <= MAX_WALL_S:
        raise DtscalError(f"--wall {wall_s}: give a time limit per check between 0 and {MAX_WALL_S:g} s "
                          f"(default {WALL_S:g})")
    if isinstance(cpu_s, bool) or not isinstance(cpu_s, int) or not 1 <= cpu_s <= MAX_CPU_S:
        raise DtscalError(f"--cpu {cpu_s}: give whole CPU seconds per check between 1 and {MAX_CPU_S} "
                          f"(default {CPU_S})")
    if mem_mb is None:
        return
    total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2 ** 20
    if isinstance(mem_mb, bool) or not isinstance(mem_mb, int) or not MIN_MEM_MB <= mem_mb <= max(total, MIN_MEM_MB):
        raise DtscalError(f"--mem {mem_mb}: give the memory per submission in MB, between {MIN_MEM_MB} (what the "
                          f"grading process itself maps) and {total} (this machine's memory); default {MEM_MB}")


#: barriers to leave out ("namespaces", "landlock"): only for tests of the fallbacks, which
#: are what a machine without them gets
WITHOUT: set[str] = set()

#: time allowed for starting the child and loading the submission
LOAD_WALL_S = 30.0
MAX_ARRAY_BYTES = 256 * 2 ** 20


@dataclass
class Call:
    """What one call of a student function gave: ``value`` (decoded), or ``error``."""

    ok: bool
    value: object = None
    error: str = ""
    not_implemented: bool = False
    stdout: str = ""
    args_after: list | None = None
    note: str = ""
    seconds: float = 0.0
    #: solving routines (OpenCV's, the kit's) the call reached inside the sandbox
    honesty: list = field(default_factory=list)


@dataclass
class CheckRun:
    """The calls of one check, or why they did not finish (``failure``)."""

    calls: list[Call] = field(default_factory=list)
    failure: str = ""


@dataclass
class SandboxRun:
    checks: dict[int, CheckRun] = field(default_factory=dict)
    load_errors: list[tuple[int, str]] = field(default_factory=list)
    notes: dict = field(default_factory=dict)


def _describe(status: str, wall: float, cpu: int, mem_mb: int) -> str:
    if status == "wall":
        return f"stopped: took longer than the {wall:g} s time limit (an endless loop?)"
    if status.startswith("signal"):
        sig = int(status.split()[1])
        if sig == signal.SIGXCPU:
            return f"stopped: used more than {cpu} s of CPU time (an endless loop?)"
        if sig == signal.SIGKILL:
            return "stopped: the process was killed (out of memory or time)"
        if sig == signal.SIGSEGV:
            return "the process crashed (segmentation fault)"
        return f"the process was ended by signal {signal.Signals(sig).name}"
    code = status.split()[1] if " " in status else status
    return f"the function ended the process (os._exit / exit status {code}) before returning"


def _decode(desc, out: Path):
    if not isinstance(desc, dict):
        return None, ""
    kind = desc.get("kind")
    if kind == "tuple":
        items = [_decode(d, out)[0] for d in desc.get("items", [])[:4]]
        return tuple(items), ""
    if kind == "none":
        return None, ""
    if kind == "object":
        return _Opaque(str(desc.get("type", "?"))[:60]), ""
    if kind == "array":
        path = (out / str(desc.get("file", ""))).resolve()
        if path.parent != out.resolve() or not path.is_file() or path.is_symlink() \
                or path.stat().st_size > MAX_ARRAY_BYTES:
            return None, "unreadable answer"
        try:
            arr = np.load(path, allow_pickle=False)
        except Exception:
            return None, "unreadable answer"
        if type(arr) is not np.ndarray:
            return None, "unreadable answer"
        return arr, str(desc.get("note", ""))[:120]
    return None, ""


class _Opaque:
    """An answer that is not numbers (e.g. an object whose ``__eq__`` always says True)."""

    def __init__(self, type_name: str):
        self.type_name = type_name

    def __repr__(self):
        return f"<a {self.type_name} object>"


def _read_results(out: Path, check_id: int, nonce: str) -> list[Call] | None:
    """The answers of one check, or None when absent, unreadable or not carrying ``nonce``
    (the token the supervisor sent when the check started: nothing written before counts)."""
    f = out / f"check_{check_id}.json"
    if not f.is_file() or f.is_symlink() or f.stat().st_size > 10 * 2 ** 20:
        return None
    try:
        data = json.loads(f.read_text())
    except Exception:
        return None
    if not isinstance(data, dict) or not nonce or data.get("nonce") != nonce:
        return None
    entries = data.get("calls")
    if not isinstance(entries, list):
        return None
    calls = []
    for e in entries[:1000]:
        if not isinstance(e, dict):
            return None
        c = Call(ok=bool(e.get("ok")), error=str(e.get("error", ""))[:400],
                 not_implemented=bool(e.get("not_implemented")), stdout=str(e.get("stdout", ""))[:4000])
        if c.ok:
            c.value, c.note = _decode(e.get("value"), out)
        try:
            c.seconds = float(e.get("time", 0.0))
        except (TypeError, ValueError):
            pass
        honesty = e.get("honesty")
        if isinstance(honesty, list):
            c.honesty = [str(h)[:80] for h in honesty[:10]]
        after = e.get("args_after")
        if isinstance(after, list):
            c.args_after = [_decode(a, out)[0] if a else None for a in after]
        calls.append(c)
    return calls


def _drain(stream, keep: int, sink: list) -> None:
    size = 0
    for chunk in iter(lambda: stream.read(65536), b""):
        if size < keep:
            sink.append(chunk[: keep - size])
        size += len(chunk)


def run_calls(statements: list[tuple[str, int]], checks: list, *, blocked_paths=(),
              mem_mb: int = MEM_MB, output_chars: int = OUTPUT_CHARS, workdir_files: dict | None = None) -> SandboxRun:
    """Run ``checks`` (each a :class:`.jobs.Job`, or ``{"id", "calls": [(name, args)], "wall", "cpu"}``) on the
    submission.

    Parameters
    ----------
    statements : the submission's import/def statements ``(source, first line)``
    checks : inputs only; the answers are judged by the caller
    blocked_paths : folders the student process may not read (grading material, solutions)
    workdir_files : ``{name: bytes}`` copied into the temporary working folder

    Returns
    -------
    SandboxRun
        A :class:`CheckRun` for every check id, with ``failure`` set for checks that did not
        finish; ``load_errors`` lists statements that failed or killed the process.
    """
    run = SandboxRun()
    skip: set[int] = set()
    checks = [as_wire(c) for c in checks]  # :class:`.jobs.Job` (the grader's plan) as the child reads it
    todo = list(checks)
    attempts = 0
    while todo and attempts < len(checks) + len(statements) + 2:
        attempts += 1
        todo = _one_child(statements, todo, skip, run, blocked_paths, mem_mb, output_chars, workdir_files or {})
    for c in todo:
        run.checks.setdefault(c["id"], CheckRun(failure="not run: the submission kept killing the grading process"))
    return run


class _ForkServer:
    """One pre-imported ``child.py --serve`` process that forks a fresh process per submission
    (saves the second that importing numpy and OpenCV costs each time). Thread-safe."""

    def __init__(self):
        self.lock = threading.Lock()
        self.proc: subprocess.Popen | None = None
        self.sock: socket.socket | None = None

    def _start(self) -> None:
        ours, theirs = socket.socketpair()
        env = {k: v for k, v in os.environ.items() if k in ("PATH", "LANG", "LC_ALL", "VIRTUAL_ENV")}
        env.update(MPLBACKEND="Agg", OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
        self.proc = subprocess.Popen([sys.executable, "-I", str(CHILD), "--serve", str(theirs.fileno())],
                                     pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, cwd="/",
                                     start_new_session=True)
        theirs.close()
        self.sock = ours

    def spawn(self, job: dict) -> tuple[int, int, int]:
        """Start ``job``; returns (pid, control pipe read end, output pipe read end)."""
        data = pickle.dumps(job)
        r_ctl, w_ctl = os.pipe()
        r_out, w_out = os.pipe()
        try:
            with self.lock:
                for attempt in (0, 1):
                    if self.proc is None or self.proc.poll() is not None:
                        self._start()
                    try:
                        socket.send_fds(self.sock, [len(data).to_bytes(8, "big")], [w_ctl, w_out])
                        self.sock.sendall(data)
                        pid = int.from_bytes(_recv_exact(self.sock, 8), "big")
                        break
                    except OSError:
                        self.close()
                        if attempt:
                            raise
        finally:
            os.close(w_ctl)
            os.close(w_out)
        return pid, r_ctl, r_out

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait()
            self.proc = None


def _recv_exact(sock: socket.socket, n: int) -> bytes:
    buf = b""
    while len(buf) < n:
        chunk = sock.recv(n - len(buf))
        if not chunk:
            raise OSError("the fork server closed its socket")
        buf += chunk
    return buf


CHILD = Path(__file__).with_name("child.py")
_SERVER = _ForkServer()
atexit.register(_SERVER.close)


class _UidSlots:
    """Concurrent submissions get different uids (as root): slot k -> a uid no account uses."""

    def __init__(self):
        self.lock, self.used = threading.Lock(), set()

    def take(self) -> int:
        with self.lock:
            k = next(i for i in range(len(self.used) + 1) if i not in self.used)
            self.used.add(k)
            return k

    def give(self, k: int) -> None:
        with self.lock:
            self.used.discard(k)


_SLOTS = _UidSlots()


def _one_child(statements, todo, skip, run, blocked_paths, mem_mb, output_chars, files) -> list[dict]:
    """One sandboxed process; returns the checks still to run (after a crash of the process itself)."""
    from .barriers import free_uid

    slot = _SLOTS.take()
    uid = free_uid(slot) if os.getuid() == 0 else None
    tmp = Path(tempfile.mkdtemp(prefix="dtscal-grade-"))  # 0700
    work, out = tmp / "work", tmp / "work" / ".answers"
    out.mkdir(parents=True)
    for name, data in files.items():
        (work / name).write_bytes(data)
    if uid is not None:  # the submission's uid owns its working folder, and nothing else
        for d in (tmp, work, out, *(work / n for n in files)):
            os.chown(d, uid, uid)
    job = {"statements": statements, "skip": sorted(skip), "checks": todo, "workdir": str(work),
           "outdir": str(out), "mem_mb": mem_mb, "output_limit": output_chars, "uid": uid,
           "blocked_paths": [str(p) for p in blocked_paths], "without": sorted(WITHOUT)}
    pid, r_ctl, r_out = _SERVER.spawn(job)
    sink: list[bytes] = []
    stdout = os.fdopen(r_out, "rb", buffering=0)
    drainer = threading.Thread(target=_drain, args=(stdout, 4000, sink), daemon=True)
    drainer.start()
    remaining = list(todo)
    by_id = {c["id"]: c for c in todo}
    loader = None
    try:
        buf = b""
        current, loading, nonce = None, None, ""
        deadline = time.monotonic() + LOAD_WALL_S
        while True:
            wait = deadline - time.monotonic()
            ready = select.select([r_ctl], [], [], max(0.0, wait))[0] if wait > 0 else []
            if not ready:  # a deadline passed: the process itself is stuck
                _kill(pid, loader)
                if current is not None:
                    run.checks[current] = CheckRun(failure=_describe("wall", by_id[current]["wall"], 0, mem_mb))
                    remaining = [c for c in remaining if c["id"] != current]
                elif loading is not None:
                    skip.add(loading)
                    run.load_errors.append((loading, "loading this statement did not finish in time; skipped"))
                return remaining
            chunk = os.read(r_ctl, 65536)
            if not chunk:  # the process died
                if current is not None:
                    run.checks[current] = CheckRun(failure="the grading process was killed during this check")
                    remaining = [c for c in remaining if c["id"] != current]
                elif loading is not None:
                    skip.add(loading)
                    run.load_errors.append((loading, "loading this statement ended the process; skipped"))
                elif not run.notes:
                    time.sleep(0.2)
                    raise RuntimeError("the grading process failed to start:\n"
                                       + b"".join(sink).decode(errors="replace")[-2000:])
                return remaining
            buf += chunk
            while b"\n" in buf:  # written by the supervisor only (no student code runs there)
                line, buf = buf.split(b"\n", 1)
                try:
                    msg = json.loads(line)
                    ev = msg.get("event")
                    if ev in ("load", "load_error", "start", "done"):
                        key = int(msg["id"] if ev in ("start", "done") else msg["k"])
                        if ev in ("start", "done") and key not in by_id:
                            continue
                except (ValueError, KeyError, TypeError, AttributeError):
                    continue
                if ev == "loader":
                    loader = int(msg.get("pid", 0)) or None
                elif ev == "sandbox":
                    run.notes = dict(msg.get("notes", {}))
                    run.notes["uid"] = uid
                elif ev == "load":
                    loading = int(msg["k"])
                elif ev == "load_error":
                    run.load_errors.append((int(msg["k"]), str(msg.get("error", ""))[:400]))
                    skip.add(int(msg["k"]))
                elif ev == "ready":
                    loading = None
                elif ev == "start":
                    current, nonce = int(msg["id"]), str(msg.get("nonce", ""))
                    deadline = time.monotonic() + by_id[current]["wall"] + 5.0
                elif ev == "done":
                    cid = int(msg["id"])
                    c = by_id[cid]
                    calls = _read_results(out, cid, nonce) if cid == current else None
                    if calls is None:
                        failure = _describe(str(msg.get("status", "")), c["wall"], c["cpu"], mem_mb)
                        run.checks[cid] = CheckRun(failure=failure)
                    else:
                        run.checks[cid] = CheckRun(calls=calls)
                    remaining = [r for r in remaining if r["id"] != cid]
                    current, nonce = None, ""
                    deadline = time.monotonic() + 30.0
                elif ev == "finished":
                    return remaining
    finally:
        _kill(pid, loader)
        left = _survivors(pid, loader, uid, pid_namespace=bool(run.notes.get("pid_namespace")))
        run.notes["survivors"] = run.notes.get("survivors", 0) + left
        os.close(r_ctl)
        drainer.join(timeout=2)
        stdout.close()
        shutil.rmtree(tmp, ignore_errors=True)
        _SLOTS.give(slot)


def _alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat[stat.rindex(")") + 2] not in "ZX"


def _survivors(sid: int, loader: int | None, uid: int | None, rounds: int = 50, pid_namespace=False) -> int:
    """Kill what is left of a submission (its session, its loader, its uid); returns how many
    processes were still alive after ``rounds`` attempts (0: nothing survives). In a PID
    namespace it is enough that its init (the loader) is gone: the kernel kills the rest."""
    if pid_namespace and loader:
        for _ in range(rounds):
            if not _alive(loader) and not _alive(sid):
                return 0
            _kill(sid, loader)
            time.sleep(0.005)
        pid_namespace = False  # the init would not die: look for everything
    found: list[int] = []
    for _ in range(rounds):
        found = []
        for d in os.listdir("/proc"):
            if not d.isdigit():
                continue
            try:
                stat = Path(f"/proc/{d}/stat").read_text()
                fields = stat[stat.rindex(")") + 2:].split()
                owner = os.stat(f"/proc/{d}").st_uid
            except (OSError, ValueError):
                continue
            if fields[0] in "ZX":
                continue
            p = int(d)
            if int(fields[3]) == sid or p == loader or (uid is not None and owner == uid):
                found.append(p)
                try:
                    os.kill(p, signal.SIGKILL)
                except OSError:
                    pass
        if not found:
            return 0
        time.sleep(0.02)
    return len(found)


def _kill(pid: int, loader: int | None = None) -> None:
    """Kill a sandboxed supervisor, everything in its session, and its loader (init of the
    submission's PID namespace: the kernel then kills every process in it)."""
    for f, p in ((os.killpg, pid), (os.kill, loader)):
        if p:
            try:
                f(p, signal.SIGKILL)
            except OSError:
                pass
