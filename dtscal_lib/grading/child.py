"""The sandboxed side of the grader: runs one submission's functions, never judges them.

Started by :mod:`dtscal_lib.grading.sandbox` as ``python -I -m dtscal_lib.grading.child``.
It reads its job (pickled by the trusted parent) from stdin, then, before any student code
runs, locks itself in:

* a new network namespace (no interface but loopback) when the kernel allows it;
* an unprivileged user (``nobody``) when started as root, so files only root may read
  stay unreadable;
* resource limits: address space (memory), file size, no core files, process count;
* a Python audit hook that refuses network sockets, subprocesses, ``ctypes`` library
  loading, reading the grading material and the solutions, and writing outside the
  temporary working folder.

It then runs the submission's import and ``def`` statements one by one (reporting each on
the control pipe, so the parent can skip a statement that kills the process), and for each
check forks a worker with its own CPU-time and memory limits that calls the functions and
writes the answers as ``.npy`` files (no pickle) for the parent to judge. A worker that
loops, crashes, exits or runs out of memory costs that check only.
"""

from __future__ import annotations

import io
import json
import os
import pickle
import resource
import signal
import sys
import time
import traceback

NOBODY = 65534
CLONE_NEWNET, CLONE_NEWUSER = 0x40000000, 0x10000000


class _Capped(io.TextIOBase):
    """A text stream that keeps the first ``limit`` characters and counts the rest."""

    def __init__(self, limit: int):
        self.limit, self.parts, self.size, self.dropped = limit, [], 0, 0

    def writable(self):
        return True

    def write(self, s):
        s = str(s)
        room = self.limit - self.size
        if room > 0:
            self.parts.append(s[:room])
            self.size += min(room, len(s))
        self.dropped += max(0, len(s) - max(room, 0))
        return len(s)

    def text(self) -> str:
        out = "".join(self.parts)
        return out + (f"\n... ({self.dropped} more characters of output dropped)" if self.dropped else "")


def _unshare_network() -> str:
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    if libc.unshare(CLONE_NEWNET) == 0:
        return "network namespace"
    if os.getuid() != 0 and libc.unshare(CLONE_NEWUSER | CLONE_NEWNET) == 0:
        return "user+network namespace"
    return "python-level socket block only"


def _world_readable(path: str) -> bool:
    """Can any user read ``path`` (every folder above it searchable)?"""
    import stat

    path = os.path.realpath(path)
    if not os.stat(path).st_mode & stat.S_IROTH:
        return False
    while path != os.path.dirname(path):
        path = os.path.dirname(path)
        if not os.stat(path).st_mode & stat.S_IXOTH:
            return False
    return True


def _lock_in(job: dict) -> dict:
    notes = {}
    try:
        notes["network"] = _unshare_network()
    except Exception as exc:  # no ctypes/libc: fall back to the audit hook
        notes["network"] = f"python-level socket block only ({exc})"
    work = job["workdir"]
    import sysconfig

    needed = [sysconfig.get_paths()["stdlib"], sysconfig.get_paths()["purelib"], os.path.dirname(__file__)]
    if os.getuid() == 0 and not all(_world_readable(p) for p in needed):
        notes["user"] = "root (Python is installed where user nobody cannot read it)"
    elif os.getuid() == 0:
        os.chown(work, NOBODY, NOBODY)
        for d in (job["outdir"],):
            os.chown(d, NOBODY, NOBODY)
        os.setgroups([])
        os.setgid(NOBODY)
        os.setuid(NOBODY)
        resource.setrlimit(resource.RLIMIT_NPROC, (64, 64))
        notes["user"] = "nobody"
    else:
        notes["user"] = "same user as the grader"
    mem = int(job["mem_mb"]) * 2 ** 20
    resource.setrlimit(resource.RLIMIT_AS, (mem, mem))
    resource.setrlimit(resource.RLIMIT_FSIZE, (64 * 2 ** 20, 64 * 2 ** 20))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a huge file write fails instead of killing
    os.chdir(work)
    os.environ["HOME"] = os.environ["MPLCONFIGDIR"] = work
    return notes


def _audit_hook(job: dict):
    blocked = tuple(os.path.realpath(p) + os.sep for p in job["blocked_paths"])
    writable = tuple(os.path.realpath(p) + os.sep for p in (job["workdir"], "/dev/null"))
    deny = {"subprocess.Popen", "os.system", "os.exec", "os.posix_spawn", "os.spawn", "pty.spawn",
            "socket.connect", "socket.bind", "socket.sendto", "socket.sendmsg", "socket.getaddrinfo",
            "ctypes.dlopen", "ctypes.dlsym", "os.chmod", "os.chown", "shutil.rmtree", "os.rmdir",
            "sys.setprofile", "sys.settrace"}
    write_flags = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_APPEND | os.O_TRUNC

    def hook(event, args):
        if event in deny:
            raise PermissionError(f"the grader does not allow {event} in submissions")
        if event in ("open", "os.remove", "os.rename", "os.replace", "os.mkdir", "os.symlink", "os.link",
                     "os.listdir", "os.scandir"):
            path = args[0] if args else None
            if isinstance(path, int) or path is None:
                return
            real = os.path.realpath(os.fsdecode(path)) + os.sep
            if real.startswith(blocked):
                raise PermissionError("the grading material is not readable by submissions")
            writing = event != "open" and event not in ("os.listdir", "os.scandir")
            if event == "open":
                mode, flags = (args[1], args[2]) if len(args) >= 3 else (None, 0)
                writing = (isinstance(mode, str) and any(c in mode for c in "wax+")) or \
                    (isinstance(flags, int) and bool(flags & write_flags))
            if writing and not real.startswith(writable):
                raise PermissionError(f"submissions may write only in their working folder, not {path}")

    sys.addaudithook(hook)


def _send(fd: int, msg: dict) -> None:
    os.write(fd, (json.dumps(msg) + "\n").encode())


def _error_text(exc: BaseException) -> str:
    tb = traceback.extract_tb(exc.__traceback__)
    frames = [f for f in tb if f.filename.startswith("<submission")]
    where = f" (line {frames[-1].lineno} in {frames[-1].name})" if frames else ""
    return f"{type(exc).__name__}: {str(exc)[:300]}{where}"


def _encode(value, out: str, stem: str, np, depth: int = 0):
    """Write ``value`` as plain arrays under ``out``; return a JSON-able description."""
    if isinstance(value, (tuple, list)) and depth == 0 and 1 <= len(value) <= 4 and \
            any(isinstance(v, (np.ndarray, tuple, list)) for v in value):
        return {"kind": "tuple", "items": [_encode(v, out, f"{stem}_{i}", np, 1) for i, v in enumerate(value)]}
    note = ""
    if isinstance(value, np.ndarray):
        if type(value) is not np.ndarray:
            note = f"an ndarray subclass ({type(value).__name__})"
        arr = np.ndarray.view(value, np.ndarray)
        if arr.dtype.kind not in "biuf":
            arr = np.array(arr.tolist(), dtype=np.float64)
    elif isinstance(value, (float, int, np.floating, np.integer)) and not isinstance(value, bool):
        arr = np.array(float(value))
    elif value is None:
        return {"kind": "none"}
    else:
        note = f"a {type(value).__name__}"
        try:
            arr = np.array(value, dtype=np.float64)
            if arr.dtype != np.float64:
                raise TypeError
            arr = np.ndarray.view(arr, np.ndarray)
        except Exception:
            return {"kind": "object", "type": type(value).__name__}
    path = os.path.join(out, stem + ".npy")
    np.save(path, arr if arr.flags.c_contiguous else arr.copy(order="C"), allow_pickle=False)
    return {"kind": "array", "file": stem + ".npy", "note": note}


def _run_check(check: dict, ns: dict, job: dict, np) -> None:
    """In the forked worker: call the functions, write ``check_<id>.json`` and the arrays."""
    cpu = max(1, int(check["cpu"]))
    resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 1))
    out = job["outdir"]
    results = []
    for src in check.get("substitute", ()):  # the grader's stand-in for a callee (one bug, one charge)
        exec(src, ns)
    real_stdout, real_stderr = sys.stdout, sys.stderr
    for k, (name, args) in enumerate(check["calls"]):
        cap = _Capped(job["output_limit"])
        sys.stdout = sys.stderr = cap
        entry = {"ok": False}
        t0 = time.perf_counter()
        try:
            fn = ns.get(name)
            if not callable(fn):
                raise NameError(f"the submission defines no function {name}")
            value = fn(*args)
            entry = {"ok": True, "value": _encode(value, out, f"c{check['id']}_{k}_v", np)}
        except NotImplementedError:
            entry = {"ok": False, "error": "NotImplementedError", "not_implemented": True}
        except MemoryError:
            entry = {"ok": False, "error": "MemoryError: ran out of memory"}
        except SystemExit as exc:
            entry = {"ok": False, "error": f"called sys.exit({exc.code!r})"}
        except RecursionError:
            entry = {"ok": False, "error": "RecursionError: maximum recursion depth exceeded"}
        except BaseException as exc:  # student code may raise anything
            entry = {"ok": False, "error": _error_text(exc)}
        entry["time"] = time.perf_counter() - t0
        sys.stdout, sys.stderr = real_stdout, real_stderr
        entry["stdout"] = cap.text()
        try:
            entry["args_after"] = [_encode(a, out, f"c{check['id']}_{k}_a{i}", np, 1)
                                   if isinstance(a, np.ndarray) else None for i, a in enumerate(args)]
        except Exception:
            entry["args_after"] = None
        results.append(entry)
        if entry.get("not_implemented"):
            break
    with open(os.path.join(out, f"check_{check['id']}.json"), "w") as f:
        json.dump(results, f)


def _wait(pid: int, wall: float) -> str:
    deadline = time.monotonic() + wall
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            if os.WIFSIGNALED(status):
                return f"signal {os.WTERMSIG(status)}"
            return f"exit {os.WEXITSTATUS(status)}"
        if time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            return "wall"
        time.sleep(0.002)


def _preload():
    os.environ.update({"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"})
    import math  # noqa: F401  (what exercise cells use, loaded before the limits)

    import cv2
    import numpy as np

    cv2.setNumThreads(1)
    try:  # the kit's facts, which exercise functions may use: imported once, before any fork
        import dtscal_lib.duckietown  # noqa: F401
        import dtscal_lib.errors  # noqa: F401
    except ImportError:
        pass
    return np


def main() -> int:
    """One submission: the job comes pickled on stdin from the trusted parent."""
    job = pickle.loads(sys.stdin.buffer.read())
    run_job(job, _preload())
    return 0


def _recv_exact(sock, n: int) -> bytes:
    buf = b""
    while len(buf) < n:
        chunk = sock.recv(min(n - len(buf), 1 << 20))
        if not chunk:
            raise EOFError
        buf += chunk
    return buf


def serve(fd: int) -> int:
    """Fork server: numpy and OpenCV are imported once; every job forks a fresh process.

    Protocol on the socket ``fd`` (from the trusted parent): 8-byte length + the control
    and output pipe ends (SCM_RIGHTS), then the pickled job; the reply is the 8-byte pid of
    the process running the job (its own session, so the parent can kill its whole group).
    """
    import socket

    np = _preload()
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)  # jobs are reaped automatically
    sock = socket.socket(fileno=fd)
    while True:
        try:
            head, fds, _, _ = socket.recv_fds(sock, 8, 2)
            if len(head) < 8:
                return 0
            job = pickle.loads(_recv_exact(sock, int.from_bytes(head, "big")))
        except (EOFError, OSError):
            return 0
        ctl, out = fds
        pid = os.fork()
        if pid == 0:
            try:
                sock.close()
                os.setsid()
                signal.signal(signal.SIGCHLD, signal.SIG_DFL)
                os.dup2(out, 1)
                os.dup2(out, 2)
                os.close(out)
                job["control_fd"] = ctl
                run_job(job, np)
            finally:
                os._exit(0)
        os.close(ctl)
        os.close(out)
        sock.sendall(pid.to_bytes(8, "big"))


def run_job(job: dict, np) -> None:
    """Lock in, load the submission statement by statement, run every check in a fork."""
    ctl = job["control_fd"]
    notes = _lock_in(job)
    _audit_hook(job)
    _send(ctl, {"event": "sandbox", "notes": notes})
    ns: dict = {"__name__": "submission", "__builtins__": __builtins__}
    for k, (src, lineno) in enumerate(job["statements"]):
        if k in job["skip"]:
            continue
        _send(ctl, {"event": "load", "k": k})
        try:
            code = compile("\n" * (lineno - 1) + src, "<submission>", "exec")
            with open(os.devnull, "w") as sink:
                old = sys.stdout, sys.stderr
                sys.stdout = sys.stderr = sink
                try:
                    exec(code, ns)
                finally:
                    sys.stdout, sys.stderr = old
        except BaseException as exc:  # noqa: BLE001 - an import that fails or a def that raises
            _send(ctl, {"event": "load_error", "k": k, "error": _error_text(exc)})
    _send(ctl, {"event": "ready"})
    for check in job["checks"]:
        _send(ctl, {"event": "start", "id": check["id"]})
        pid = os.fork()
        if pid == 0:
            try:
                os.close(ctl)
                _run_check(check, ns, job, np)
            finally:
                os._exit(0)
        status = _wait(pid, float(check["wall"]))
        _send(ctl, {"event": "done", "id": check["id"], "status": status})
    _send(ctl, {"event": "finished"})


if __name__ == "__main__":
    sys.exit(serve(int(sys.argv[2])) if sys.argv[1:2] == ["--serve"] else main())
