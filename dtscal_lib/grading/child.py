"""The sandboxed side of the grader: runs one submission's functions, never judges them.

Started once by :mod:`dtscal_lib.grading.sandbox` as ``python -I child.py --serve FD``: a
fork server that imports numpy and OpenCV once, then forks, per submission:

* a **supervisor** (trusted, runs no student code): it owns the control pipe to the grader,
  enters new namespaces (PID, network, and as root a private mount namespace covering the
  grading material with an empty tmpfs; see :mod:`.barriers`), forks the loader, and relays
  the loader's messages only when they fit the protocol (a message written by student code
  while it loads can neither start nor finish a check); each check starts with a random
  token, and its answers count only if they carry it;
* a **loader** (init of the PID namespace): before any student code it closes everything of
  the supervisor's, becomes a fresh uid (root), applies Landlock (writes only in the working
  folder, no exec, the material unreadable, no TCP, no signals outside the submission),
  resource limits, a Python audit hook, and replaces OpenCV's and the kit's solving routines
  by stubs that record the call (run-time academic honesty). It then runs the submission's
  import and ``def`` statements one by one (reporting each, so the grader can skip one that
  kills the process);
* per check, a **worker** forked from the loader, with its own CPU-time limit, which calls
  the functions and writes the answers as ``.npy`` files (no pickle). After each check the
  loader kills every other process of the namespace; when the loader dies, the kernel kills
  the rest. A worker that loops, crashes, exits or runs out of memory costs that check only.
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


def _namespaces(job: dict) -> dict:
    """In the supervisor, before the loader forks: new PID (+ network, + mount as root) namespaces.

    Returns notes. The loader forked next is init of the PID namespace: when it dies, the
    kernel kills every process the submission started.
    """
    from dtscal_lib.grading import barriers

    notes = {}
    if "namespaces" in job.get("without", ()):
        return {"processes": "process group (namespaces turned off); survivors are looked for and killed",
                "pid_namespace": False, "network": "no network namespace (turned off)"}
    root = os.getuid() == 0
    # a mount namespace (25 ms per submission, measured) only where Landlock does not already
    # hide the material
    mounts = root and not barriers.landlock_abi()
    want = barriers.CLONE_NEWPID | barriers.CLONE_NEWNET | (barriers.CLONE_NEWNS if mounts else 0)
    tries = [want, barriers.CLONE_NEWPID] if root else \
        [barriers.CLONE_NEWUSER | want, barriers.CLONE_NEWUSER | barriers.CLONE_NEWPID]
    got = 0
    uid, gid = os.getuid(), os.getgid()
    for flags in tries:
        try:
            barriers.unshare(flags)
        except OSError as exc:
            notes["namespaces_error"] = str(exc)
            continue
        got = flags
        if flags & barriers.CLONE_NEWUSER:  # map our own ids (unmapped, files are still ours on disk)
            try:
                for name, text in (("setgroups", "deny"), ("uid_map", f"{uid} {uid} 1"), ("gid_map", f"{gid} {gid} 1")):
                    with open(f"/proc/self/{name}", "w") as f:
                        f.write(text)
            except OSError as exc:
                notes["user_namespace"] = f"ids not mapped ({exc})"
        break
    if got & barriers.CLONE_NEWNS:
        try:
            barriers.hide_folders(job["blocked_paths"])
            notes["mounts"] = "private mount namespace: the grading material is covered by an empty tmpfs"
        except OSError as exc:
            notes["mounts"] = f"private mount namespace, material not covered ({exc})"
    notes["processes"] = ("PID namespace: every process the submission starts dies with it"
                          if got & barriers.CLONE_NEWPID else
                          "process group (no PID namespace here); survivors are looked for and killed")
    notes["network"] = "network namespace (loopback only)" if got & barriers.CLONE_NEWNET else \
        "no network namespace (Landlock/audit hook refuse connections)"
    notes["pid_namespace"] = bool(got & barriers.CLONE_NEWPID)
    return notes


def _lock_in(job: dict) -> dict:
    """In the loader, before any student code: uid, Landlock, resource limits, working folder."""
    from dtscal_lib.grading import barriers

    notes = {}
    work = job["workdir"]
    import sysconfig

    needed = [sysconfig.get_paths()["stdlib"], sysconfig.get_paths()["purelib"], os.path.dirname(__file__)]
    uid = int(job.get("uid") or NOBODY)
    abi = 0 if "landlock" in job.get("without", ()) else barriers.landlock_abi()
    if os.getuid() == 0:
        readable = all(_world_readable(p) for p in needed)
        try:  # even with the right to read any file, a fresh uid holds far less than root
            barriers.become(uid, read_everything=not readable)
            resource.setrlimit(resource.RLIMIT_NPROC, (64, 64))
            notes["user"] = f"uid {uid} (fresh for this submission, owns only its working folder" + \
                ("; may read any file but the material, as Python is installed where others cannot read)"
                 if not readable else ")")
        except OSError as exc:
            notes["user"] = f"root ({exc})"
    else:
        notes["user"] = "same user as the grader"
    try:
        barriers.set_pdeathsig(signal.SIGKILL)  # after setuid, which clears it
    except OSError:
        pass
    if abi:
        try:
            notes["files"] = barriers.landlock([work], job["blocked_paths"], abi)
        except OSError as exc:
            notes["files"] = f"Landlock refused ({exc}); audit hook only"
    else:
        notes["files"] = "no Landlock in this kernel: audit hook" + (" and uid/folder permissions"
                                                                       if notes["user"].startswith("uid") else "")
    mem = int(job["mem_mb"]) * 2 ** 20
    resource.setrlimit(resource.RLIMIT_AS, (mem, mem))
    resource.setrlimit(resource.RLIMIT_FSIZE, (64 * 2 ** 20, 64 * 2 ** 20))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a huge file write fails instead of killing
    os.chdir(work)
    os.environ["HOME"] = os.environ["MPLCONFIGDIR"] = work
    return notes


class AcademicHonestyError(PermissionError):
    """Raised by a solving routine called from a submission inside the sandbox."""


def _poison_solvers(used: list) -> None:
    """Replace OpenCV's and the kit's solving routines before the submission loads.

    Every route to them (``importlib``, ``sys.modules``, ``vars``, ``__dict__``, ``eval``,
    ``builtins.__import__``, ``globals()``) reaches the same module objects, so it reaches
    the stubs: a call is recorded in ``used`` (read by the worker after each call) and fails.
    """
    import importlib.abc
    import importlib.machinery
    import types

    from dtscal_lib.grading.loader import CV2_DENY, KIT_ALLOWED

    def stub(qual):
        def solver(*args, **kwargs):
            used.append(qual)
            raise AcademicHonestyError(f"{qual} does the exercise for you: submissions may not call it")
        solver.__name__ = solver.__qualname__ = qual.rsplit(".", 1)[-1]
        return solver

    for name, mod in list(sys.modules.items()):
        if name == "cv2" or name.startswith("cv2."):
            for attr in CV2_DENY:
                if attr in getattr(mod, "__dict__", {}):
                    try:
                        setattr(mod, attr, stub(f"cv2.{attr}"))
                    except (AttributeError, TypeError):
                        pass

    class Poisoned(types.ModuleType):
        def __init__(self, name):
            super().__init__(name)
            self.__path__ = []  # a package: its submodules come from the Finder below

        def __getattr__(self, attr):
            if attr.startswith("__"):
                raise AttributeError(attr)
            return stub(f"{self.__name__}.{attr}")

    def allowed(name):
        return any(name == m or name.startswith(m + ".") for m in KIT_ALLOWED) or name == "dtscal_lib"

    for name in list(sys.modules):
        if name.startswith("dtscal_lib.") and not allowed(name):
            sys.modules[name] = Poisoned(name)
    for name, mod in list(sys.modules.items()):  # the names packages hold: dtscal_lib.calibrate, ...
        if name != "dtscal_lib" and not (name.startswith("dtscal_lib.") and allowed(name)):
            continue
        for attr, value in list(vars(mod).items()):
            origin = value.__name__ if isinstance(value, types.ModuleType) else getattr(value, "__module__", "")
            if not isinstance(origin, str) or not origin.startswith("dtscal_lib.") or allowed(origin):
                continue
            if isinstance(value, types.ModuleType):
                setattr(mod, attr, sys.modules.get(origin) or Poisoned(origin))
            elif callable(value):
                setattr(mod, attr, stub(f"{origin}.{attr}"))

    class Finder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
        def find_spec(self, name, path=None, target=None):
            if name.startswith("dtscal_lib.") and not allowed(name):
                return importlib.machinery.ModuleSpec(name, self, is_package=True)
            return None

        def create_module(self, spec):
            return Poisoned(spec.name)

        def exec_module(self, module):
            pass

    sys.meta_path.insert(0, Finder())


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
            if event in ("os.rename", "os.replace", "os.symlink", "os.link") and len(args) >= 2 \
                    and not isinstance(args[1], int) and args[1] is not None:
                second = os.path.realpath(os.fsdecode(args[1])) + os.sep
                if not second.startswith(writable):
                    raise PermissionError(f"submissions may write only in their working folder, not {args[1]}")
            path = args[0] if args else None
            if isinstance(path, int) or path is None:
                return
            real = os.path.realpath(os.fsdecode(path)) + os.sep
            if real.startswith(blocked):
                raise PermissionError("the grading material is not readable by submissions")
            writing = event != "open" and event not in ("os.listdir", "os.scandir", "os.symlink")
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


def _run_check(check: dict, ns: dict, job: dict, np, nonce: str, used: list) -> None:
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
        del used[:]
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
        if used:
            entry["honesty"] = sorted(set(used))[:10]
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
        json.dump({"nonce": nonce, "calls": results}, f)


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
    kit = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    sys.path.insert(0, kit)  # the kit this file belongs to (not another checkout's)
    try:  # the kit's facts, which exercise functions may use: imported once, before any fork
        import dtscal_lib.duckietown  # noqa: F401
        import dtscal_lib.errors  # noqa: F401
        import dtscal_lib.grading.barriers  # noqa: F401
        import dtscal_lib.grading.loader  # noqa: F401
    finally:
        sys.path.remove(kit)
    return np


def _recv_exact(sock, n: int) -> bytes:
    buf = b""
    while len(buf) < n:
        chunk = sock.recv(min(n - len(buf), 1 << 20))
        if not chunk:
            raise EOFError
        buf += chunk
    return buf


def serve(fd: int) -> int:
    """Fork server: numpy and OpenCV are imported once; every job forks a fresh supervisor.

    Protocol on the socket ``fd`` (from the trusted parent): 8-byte length + the control
    and output pipe ends (SCM_RIGHTS), then the pickled job; the reply is the 8-byte pid of
    the supervisor (its own session, so the parent can kill its whole group).
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
                supervise(job, np, ctl)
            finally:
                os._exit(0)
        os.close(ctl)
        os.close(out)
        sock.sendall(pid.to_bytes(8, "big"))


def supervise(job: dict, np, ctl: int) -> None:
    """The trusted end of one submission: owns the control pipe, runs no student code.

    It enters new namespaces, forks the loader (init of the PID namespace), and relays the
    loader's messages to the grader only when they fit the protocol's state: a message
    written by student code while it loads cannot start or finish a check, and each check's
    answers must carry the random token this process sends when the check starts.
    """
    notes = {}
    try:
        notes = _namespaces(job)
    except Exception as exc:  # noqa: BLE001 - no namespaces: the other barriers still hold
        notes = {"processes": f"process group ({exc})", "pid_namespace": False}
    up_r, up_w = os.pipe()
    down_r, down_w = os.pipe()
    loader = os.fork()
    if loader == 0:
        try:
            os.close(ctl)
            os.close(up_r)
            os.close(down_w)
            load_and_run(job, np, up_w, down_r)
        finally:
            os._exit(0)
    os.close(up_w)
    os.close(down_r)
    _send(ctl, {"event": "loader", "pid": loader})
    order = [int(c["id"]) for c in job["checks"]]
    n_statements = len(job["statements"])
    state, current, buf = "start", None, b""
    reader = os.fdopen(up_r, "rb", buffering=0)
    while True:
        chunk = reader.read(65536)
        if not chunk:
            break
        buf += chunk
        while b"\n" in buf:
            line, buf = buf.split(b"\n", 1)
            if len(line) > 100000:
                continue
            try:
                msg = json.loads(line)
                ev = msg["event"]
            except (ValueError, KeyError, TypeError):
                continue
            if state == "start" and ev == "sandbox":
                notes.update({k: str(v)[:300] for k, v in dict(msg.get("notes", {})).items()})
                _send(ctl, {"event": "sandbox", "notes": notes})
                state = "loading"
            elif state == "loading" and ev in ("load", "load_error"):
                try:
                    k = int(msg["k"])
                except (KeyError, TypeError, ValueError):
                    continue
                if 0 <= k < n_statements:
                    _send(ctl, {"event": ev, "k": k, "error": str(msg.get("error", ""))[:400]})
            elif state == "loading" and ev == "ready":
                state = "checks"
                _send(ctl, {"event": "ready"})
                current = _start_next(order, None, ctl, down_w)
            elif state == "checks" and ev == "done" and current is not None and msg.get("id") == current[0]:
                _send(ctl, {"event": "done", "id": current[0], "status": str(msg.get("status", ""))[:40]})
                current = _start_next(order, current[0], ctl, down_w)
                if current is None:
                    _send(ctl, {"event": "finished"})
                    state = "finished"
                    os.close(down_w)
    os.close(ctl)
    try:
        os.kill(loader, signal.SIGKILL)
    except OSError:
        pass
    os.waitpid(loader, 0)


def _start_next(order: list, after, ctl: int, down: int):
    """Send the next check's start (with a fresh token) to the grader and the loader."""
    i = 0 if after is None else order.index(after) + 1
    if i >= len(order):
        return None
    cid, nonce = order[i], os.urandom(16).hex()
    _send(ctl, {"event": "start", "id": cid, "nonce": nonce})
    try:
        _send(down, {"id": cid, "nonce": nonce})
    except OSError:
        pass
    return cid, nonce


def _read_order(down_file):
    line = down_file.readline()
    if not line:
        raise EOFError
    return json.loads(line)


def load_and_run(job: dict, np, up: int, down: int) -> None:
    """The loader: lock in, load the submission statement by statement, run each check in a fork.

    With a PID namespace this process is its init: after each check it kills every process
    left in the namespace (the worker's children), and when it dies the kernel kills the rest.
    """
    signal.signal(signal.SIGCHLD, signal.SIG_DFL)
    kill, getpid, waitpid = os.kill, os.getpid, os.waitpid
    used: list = []
    notes = {}
    try:
        notes = _lock_in(job)
    except Exception as exc:  # noqa: BLE001
        notes = {"lock_in_error": f"{type(exc).__name__}: {exc}"}
    _audit_hook(job)
    _poison_solvers(used)
    notes["honesty"] = "OpenCV's and the kit's solving routines replaced by stubs before loading"
    _send(up, {"event": "sandbox", "notes": notes})
    down_file = os.fdopen(down, "rb")
    ns: dict = {"__name__": "submission", "__builtins__": __builtins__}
    for k, (src, lineno) in enumerate(job["statements"]):
        if k in job["skip"]:
            continue
        _send(up, {"event": "load", "k": k})
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
            _send(up, {"event": "load_error", "k": k, "error": _error_text(exc)})
    _send(up, {"event": "ready"})
    by_id = {int(c["id"]): c for c in job["checks"]}
    while True:
        try:
            order = _read_order(down_file)
        except (EOFError, ValueError):
            break
        check = by_id[int(order["id"])]
        pid = os.fork()
        if pid == 0:
            try:
                os.setpgid(0, 0)  # its own group: without a PID namespace, killed with it below
                _run_check(check, ns, job, np, order["nonce"], used)
            finally:
                os._exit(0)
        status = _wait(pid, float(check["wall"]))
        if getpid() != 1:  # no PID namespace: the check's process group at least
            try:
                os.killpg(pid, signal.SIGKILL)
            except OSError:
                pass
        else:  # init of the namespace: nothing the check started survives it
            try:
                kill(-1, signal.SIGKILL)
            except OSError:
                pass
            try:  # reap them all (killed, they die at once), so none counts against the process limit
                while True:
                    waitpid(-1, 0)
            except ChildProcessError:
                pass
        _send(up, {"event": "done", "id": check["id"], "status": status})


if __name__ == "__main__":
    sys.exit(serve(int(sys.argv[2])) if sys.argv[1:2] == ["--serve"] else 2)
