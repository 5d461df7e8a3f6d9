"""The harness inside the grading sandbox: runs one submission's functions, never judges them.

:mod:`dtscal_lib.grading.sandbox` starts it as ``python -I -S harness.py`` inside bubblewrap
(or, where bubblewrap cannot run, as a bare process). It imports nothing of the kit: only the
standard library, numpy and :mod:`seccomp` (copied beside it). Its three kinds of process:

* the **zygote** (this script's main process; trusted, runs no student code): reads the job
  (:class:`SandboxJob`, typed) on stdin, makes itself undumpable (so no process of the
  submission can open its ``/proc/PID/mem`` or ``fd/``), refuses ``execve`` for itself and all
  its children (:func:`seccomp.no_exec_filter`), imports numpy, then forks a loader probe and
  one worker per check. It alone writes on the grader's channel (a descriptor no worker keeps);
  each worker answers on its own pipe, so what a worker writes counts for its own check only;
* the **probe**: loads the submission's statements one by one and reports each, so that a
  statement that fails or kills the process is skipped by the workers;
* a **worker** per check: closes every descriptor but its answer pipe, takes its memory and
  CPU limits and :func:`seccomp.worker_filter` (no new process or thread, signals to itself
  only), loads the statements, calls the functions and writes the answers as plain ``.npy``
  arrays, each once, in one length-prefixed frame.

What an exercise forbids (OpenCV, the kit's solving modules) is absent from the sandbox's
files; a meta-path finder turns the import into an error naming the rule (a top-level
``import cv2``, course plumbing, gives a module that holds nothing and names the rule when
touched) and records the attempt, which the grader reports as an academic-honesty finding.
"""

from __future__ import annotations

import io
import json
import os
import pickle
import resource
import signal
import struct
import sys
import time
import traceback
from dataclasses import dataclass, field

#: caps on one worker's answer frame (the grader applies them again when it decodes). The largest
#: answer of the kit's checks: notebook 04's stand-in run of rectification_maps, 5 cases of two
#: 640x480 float64 maps (5 x 4.9 MB = 25 MB): 64 MB leaves 2.5x room
MAX_HEADER_BYTES = 4 * 2 ** 20
MAX_BLOBS = 512
MAX_ANSWER_BYTES = 64 * 2 ** 20
ANSWER_MARK = b"DTSCAL01"


@dataclass
class CheckJob:
    """One check to run in the sandbox: inputs only (the expected answers stay with the grader)."""

    id: int
    calls: list  # [(function name, args tuple)]
    wall: float
    cpu: int
    substitute: list = field(default_factory=list)  # sources of the grader's stand-ins, run first


@dataclass
class SandboxJob:
    """Everything the harness needs for one submission."""

    statements: list  # [(source, first line)]
    checks: list  # [CheckJob]
    skip: list = field(default_factory=list)  # statements known to fail or kill the process
    mem_mb: int = 2048
    output_limit: int = 2000
    load_wall: float = 30.0
    workdir: str = "/tmp"
    workdir_files: dict = field(default_factory=dict)
    #: OpenCV routines whose use is an academic-honesty finding
    cv2_deny: list = field(default_factory=list)
    #: kit modules an exercise may use (they are the only ones in the sandbox)
    kit_allowed: list = field(default_factory=list)
    #: where the kit's allowed modules are (a folder holding ``dtscal_lib/``)
    kit_dir: str = ""
    #: "bubblewrap" (filter 1 already applied by bwrap) or "bare" (the harness applies it)
    mode: str = "bubblewrap"


class _Unpickler(pickle.Unpickler):
    """The job's classes and numpy arrays, nothing else."""

    def find_class(self, module, name):
        if name in ("CheckJob", "SandboxJob") and module in ("dtscal_lib.grading.harness", "__main__", "harness"):
            return {"CheckJob": CheckJob, "SandboxJob": SandboxJob}[name]
        if module.split(".")[0] == "numpy" or (module, name) in (("builtins", "slice"), ("builtins", "complex")):
            return super().find_class(module, name)
        raise pickle.UnpicklingError(f"{module}.{name} is not part of a grading job")


# --------------------------------------------------------------------------- frames


def frame(header: dict, blobs: list[bytes] = ()) -> bytes:
    """4-byte length + JSON header (with the blob sizes) + the blobs."""
    header = dict(header, blobs=[len(b) for b in blobs])
    head = json.dumps(header).encode()
    return struct.pack(">I", len(head)) + head + b"".join(blobs)


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        n = os.write(fd, view)
        view = view[n:]


# --------------------------------------------------------------------------- the rule


class _Rule:
    """Imports of what the exercise forbids fail with a message naming the rule."""

    def __init__(self, job: SandboxJob):
        self.deny = set(job.cv2_deny)
        self.allowed = tuple(job.kit_allowed)
        self.used: list[str] = []
        self.recording = False
        self.loading = True

    def message(self, name: str) -> str:
        if name.split(".")[0] in ("cv2", "cv"):
            return (f"{name} is not allowed in this exercise: OpenCV is not installed in the grading sandbox; "
                    "write the computation yourself with numpy")
        return (f"{name} is not allowed in this exercise: the kit's own solving code is not in the grading "
                "sandbox (only " + ", ".join(self.allowed) + " are); write the computation yourself")

    def forbidden(self, name: str) -> bool:
        top = name.split(".")[0]
        if top in ("cv2", "cv"):
            return True
        if top == "dtscal_lib" and name != "dtscal_lib":
            return not any(name == m or name.startswith(m + ".") for m in self.allowed)
        return False

    def record(self, name: str) -> None:
        if self.recording and name not in self.used:
            self.used.append(name)

    def find_spec(self, name, path=None, target=None):
        if not self.forbidden(name):
            return None
        if self.loading and name == "cv2":  # the course's `import cv2` at the top of a notebook
            import importlib.machinery

            return importlib.machinery.ModuleSpec(name, self)
        if name not in ("cv2", "cv"):  # importing OpenCV is no finding; reaching for a solver is
            self.record(name)
        raise ImportError(self.message(name), name=name)

    def create_module(self, spec):
        import types

        rule = self

        class Absent(types.ModuleType):
            def __getattribute__(self, attr):  # every route to a name: getattr, __getattribute__, from-import
                if attr.startswith("__") and attr.endswith("__") and attr != "__dict__":
                    return super().__getattribute__(attr)
                if attr in rule.deny or attr.startswith("_"):
                    rule.record(f"cv2.{attr}")
                raise ImportError(rule.message(f"cv2.{attr}"), name="cv2")

        return Absent(spec.name)

    def exec_module(self, module):
        pass

    def install(self, kit_dir: str) -> None:
        import types

        sys.meta_path.insert(0, self)
        if kit_dir:
            rule = self
            pkg = types.ModuleType("dtscal_lib")
            pkg.__path__ = [os.path.join(kit_dir, "dtscal_lib")]

            def __getattr__(attr):  # noqa: N807 - a module's attribute hook (PEP 562)
                if attr.startswith("__"):
                    raise AttributeError(attr)
                name = f"dtscal_lib.{attr}"
                if rule.forbidden(name):
                    rule.record(name)
                    raise ImportError(rule.message(name), name=name)
                raise AttributeError(attr)

            pkg.__getattr__ = __getattr__
            sys.modules["dtscal_lib"] = pkg


# --------------------------------------------------------------------------- student side


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


def _error_text(exc: BaseException) -> str:
    tb = traceback.extract_tb(exc.__traceback__)
    frames = [f for f in tb if f.filename.startswith("<submission")]
    where = f" (line {frames[-1].lineno} in {frames[-1].name})" if frames else ""
    return f"{type(exc).__name__}: {str(exc)[:300]}{where}"


class _Blobs:
    def __init__(self):
        self.items: list[bytes] = []
        self.size = 0

    def add(self, arr, np) -> int:
        buf = io.BytesIO()
        np.save(buf, arr if arr.flags.c_contiguous else arr.copy(order="C"), allow_pickle=False)
        data = buf.getvalue()
        if len(self.items) >= MAX_BLOBS or self.size + len(data) > MAX_ANSWER_BYTES:
            raise MemoryError("the answers are larger than the grader accepts")
        self.items.append(data)
        self.size += len(data)
        return len(self.items) - 1


def _encode(value, blobs: _Blobs, np, depth: int = 0):
    """``value`` as a JSON-able description; its arrays go to ``blobs`` (plain .npy, no pickle)."""
    if isinstance(value, (tuple, list)) and depth == 0 and 1 <= len(value) <= 4 and \
            any(isinstance(v, (np.ndarray, tuple)) for v in value):  # several outputs (a nested list is one)
        items = [_encode(v, blobs, np, 1) for v in value]
        # the same words as dtscal_lib.exercise_rules.answer_note (the rule table's return-type rule)
        note = "a list" if isinstance(value, list) else next(
            (f"{it['note']} inside the tuple" for it in items if it.get("note")), "")
        return {"kind": "tuple", "items": items, "note": note}
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
            return {"kind": "object", "type": type(value).__name__[:60]}
    return {"kind": "array", "blob": blobs.add(arr, np), "note": note}


def _load(job: SandboxJob, ns: dict, report=None) -> None:
    """Run the submission's statements (minus those to skip) into ``ns``."""
    for k, (src, lineno) in enumerate(job.statements):
        if k in job.skip:
            continue
        if report:
            report({"event": "load", "k": k})
        try:
            code = compile("\n" * (lineno - 1) + src, "<submission>", "exec")
            with open(os.devnull, "w") as sink:
                old = sys.stdout, sys.stderr
                sys.stdout = sys.stderr = sink
                try:
                    exec(code, ns)
                finally:
                    sys.stdout, sys.stderr = old
        except BaseException as exc:  # noqa: BLE001 - an import that fails, a def that raises
            if report:
                report({"event": "load_error", "k": k, "error": _error_text(exc)})


def _become_worker(keep: int, mem_mb: int, cpu: int | None) -> None:
    """Before any student code in a forked process: nothing of the zygote's, limits, filter 3."""
    import seccomp

    devnull = os.open(os.devnull, os.O_RDWR)
    for fd in (0, 1, 2):
        os.dup2(devnull, fd)
    os.closerange(3, keep)
    os.closerange(keep + 1, 1 << 16)
    mem = int(mem_mb) * 2 ** 20
    resource.setrlimit(resource.RLIMIT_AS, (mem, mem))
    if cpu:
        resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 1))
    if seccomp.supported():
        seccomp.install(seccomp.worker_filter(os.getpid()))


def _probe(job: SandboxJob, w: int, rule: _Rule) -> None:
    _become_worker(w, job.mem_mb, None)
    ns: dict = {"__name__": "submission", "__builtins__": __builtins__}
    # each message on a line of its own, even after stray bytes student code wrote on the pipe
    _load(job, ns, lambda msg: _write_all(w, ("\n" + json.dumps(msg) + "\n").encode()))
    _write_all(w, b'\n{"event": "ready"}\n')


def _work(job: SandboxJob, check: CheckJob, w: int, rule: _Rule, np) -> None:
    _become_worker(w, job.mem_mb, max(1, int(check.cpu)))
    ns: dict = {"__name__": "submission", "__builtins__": __builtins__}
    _load(job, ns)
    rule.loading = False
    for src in check.substitute:  # the grader's stand-in for a callee (one bug, one charge)
        exec(src, ns)
    blobs = _Blobs()
    results = []
    real = sys.stdout, sys.stderr
    for name, args in check.calls:
        cap = _Capped(job.output_limit)
        sys.stdout = sys.stderr = cap
        del rule.used[:]
        rule.recording = True
        t0 = time.perf_counter()
        try:
            fn = ns.get(name)
            if not callable(fn):
                raise NameError(f"the submission defines no function {name}")
            value = fn(*args)
            rule.recording = False
            entry = {"ok": True, "value": _encode(value, blobs, np)}
        except NotImplementedError:
            entry = {"ok": False, "error": "NotImplementedError", "not_implemented": True}
        except MemoryError as exc:
            entry = {"ok": False, "error": f"MemoryError: ran out of memory ({str(exc)[:200]})"}
        except SystemExit as exc:
            entry = {"ok": False, "error": f"called sys.exit({exc.code!r})"}
        except RecursionError:
            entry = {"ok": False, "error": "RecursionError: maximum recursion depth exceeded"}
        except BaseException as exc:  # noqa: BLE001 - student code may raise anything
            entry = {"ok": False, "error": _error_text(exc)}
        rule.recording = False
        entry["time"] = time.perf_counter() - t0
        sys.stdout, sys.stderr = real
        if rule.used:
            entry["honesty"] = list(rule.used)[:10]
        entry["stdout"] = cap.text()
        try:
            entry["args_after"] = [_encode(a, blobs, np, 1) if isinstance(a, (np.ndarray, list)) else None
                                  for a in args]
        except Exception:  # noqa: BLE001
            entry["args_after"] = None
        results.append(entry)
        if entry.get("not_implemented"):
            break
    answer = frame({"calls": results}, blobs.items)
    # the answer is the last thing written (no student code runs after): its length and a mark
    # close it, so bytes student code wrote on the pipe before are ignored
    _write_all(w, answer + struct.pack(">Q", len(answer)) + ANSWER_MARK)


# --------------------------------------------------------------------------- zygote


def _read_capped(fd: int, deadline: float, limit: int) -> tuple[bytes, bool]:
    """Read ``fd`` to its end (or to ``deadline``); returns (data, ended in time)."""
    import select

    chunks, size = [], 0
    while True:
        left = deadline - time.monotonic()
        if left <= 0 or not select.select([fd], [], [], left)[0]:
            return b"".join(chunks), False
        chunk = os.read(fd, 1 << 20)
        if not chunk:
            return b"".join(chunks), True
        if size < limit:
            chunks.append(chunk[: limit - size])
        size += len(chunk)


def _reap(pid: int, deadline: float) -> str:
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
        time.sleep(0.001)


def _fork(target) -> tuple[int, int]:
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:
        try:
            os.close(r)
            target(w)
        finally:
            os._exit(0)
    os.close(w)
    return pid, r


def main() -> int:
    # before numpy loads (unpickling the job loads it): OpenBLAS starts no thread pool, which the
    # worker filter would refuse mid-computation
    os.environ.update({"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"})
    channel = os.dup(1)  # the grader's channel: no worker keeps it
    devnull = os.open(os.devnull, os.O_RDWR)
    os.dup2(devnull, 1)
    size = struct.unpack(">Q", _read_exact(0, 8))[0]
    job: SandboxJob = _Unpickler(io.BytesIO(_read_exact(0, size))).load()
    os.dup2(devnull, 0)
    import ctypes

    import seccomp

    notes = {}
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(4, 0, 0, 0, 0)  # PR_SET_DUMPABLE 0: no /proc/<zygote>/mem, fd/ for the workers
    libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    resource.setrlimit(resource.RLIMIT_FSIZE, (64 * 2 ** 20, 64 * 2 ** 20))
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a huge file write fails instead of killing
    if seccomp.supported():
        if job.mode != "bubblewrap":
            seccomp.install(seccomp.sandbox_filter())
        seccomp.install(seccomp.no_exec_filter())
        notes["seccomp"] = ("no exec, no ptrace/mount/unshare/bpf/keyctl/memfd/io_uring/sockets; student code: "
                            "no new process or thread, signals only to itself")
    else:
        notes["seccomp"] = "none (no system-call table for this architecture)"
    os.environ.update({"HOME": job.workdir, "MPLCONFIGDIR": job.workdir})
    os.chdir(job.workdir)
    for name, data in job.workdir_files.items():
        with open(os.path.basename(name), "wb") as f:
            f.write(data)
    import math  # noqa: F401  (what exercise cells use, loaded once here)

    import numpy as np

    rule = _Rule(job)
    rule.install(job.kit_dir)

    def send(header: dict, blobs=()) -> None:
        _write_all(channel, frame(header, blobs))

    send({"event": "hello", "notes": notes, "pid": os.getpid()})
    # the probe: which statements load (a statement that kills the process is skipped from then on)
    n = len(job.statements)
    t_end = time.monotonic() + job.load_wall
    hard_end = time.monotonic() + load_budget(job.load_wall)
    while True:
        pid, r = _fork(lambda w: _probe(job, w, rule))
        data, ended = _read_capped(r, t_end, 1 << 20)
        os.close(r)
        status = _reap(pid, time.monotonic() if not ended else time.monotonic() + 5)
        current, ready = None, False
        for line in data.split(b"\n"):
            try:
                msg = json.loads(line)
                ev, k = msg.get("event"), msg.get("k")
            except (ValueError, AttributeError):
                continue
            if ev == "ready":
                ready = True
            elif isinstance(k, int) and 0 <= k < n and k not in job.skip:
                if ev == "load":
                    current = k
                elif ev == "load_error" and k == current:
                    send({"event": "load_error", "k": k, "error": str(msg.get("error", ""))[:400]})
                    job.skip.append(k)
                    current = None
        if ready or current is None:
            break
        job.skip.append(current)
        why = "did not finish in time" if not ended else f"ended the process ({status})"
        send({"event": "load_error", "k": current, "error": f"loading this statement {why}; skipped"})
        if time.monotonic() >= hard_end:  # the submission's own load time is spent: the rest is not run
            for k in range(current + 1, n):
                if k not in job.skip:
                    job.skip.append(k)
                    send({"event": "load_error", "k": k, "error": "not loaded: loading the statements before "
                          f"it took longer than {load_budget(job.load_wall):g} s in all; skipped"})
            break
        t_end = min(max(t_end, time.monotonic() + 5), hard_end)
    send({"event": "ready", "skip": sorted(job.skip)})
    for check in job.checks:
        pid, r = _fork(lambda w, c=check: _work(job, c, w, rule, np))
        deadline = time.monotonic() + float(check.wall)
        data, ended = _read_capped(r, deadline, MAX_ANSWER_BYTES + MAX_HEADER_BYTES + 16)
        os.close(r)
        status = _reap(pid, deadline if ended else time.monotonic())
        if not ended and status != "wall":
            status = "wall"
        send({"event": "check", "id": check.id, "status": status}, [data] if status == "exit 0" else [])
    send({"event": "finished"})
    return 0


def load_budget(load_wall: float) -> float:
    """The longest the harness spends loading a submission (top-level code, default arguments)
    before it answers "ready": ``load_wall`` for the first try, then 5 s per statement skipped,
    never more than twice ``load_wall`` in all. The grader waits this long plus a margin, so
    slow loading is charged to the submission (its statements skipped), never a grader retry."""
    return 2 * float(load_wall)


def _read_exact(fd: int, n: int) -> bytes:
    buf = bytearray()
    while len(buf) < n:
        chunk = os.read(fd, min(n - len(buf), 1 << 20))
        if not chunk:
            raise EOFError("the grader closed the job pipe")
        buf += chunk
    return bytes(buf)


if __name__ == "__main__":
    sys.exit(main())
