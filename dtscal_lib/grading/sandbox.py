"""The trusted side of the sandbox: start bubblewrap per submission, read its answers, never trust it.

:func:`run_calls` hands the submission's statements and the checks' inputs (never the
expected answers), typed as :class:`CheckJob` / :class:`SandboxJob`, to
:mod:`dtscal_lib.grading.harness`, which runs inside a bubblewrap sandbox
(``bwrap``, Debian's ``bubblewrap``; :func:`bwrap_argv`) that holds only its :class:`Manifest`
(:func:`manifest`), read-only:

* the interpreter and its standard library (minus :data:`STDLIB_LEFT_OUT` and
  :data:`DYNLOAD_LEFT_OUT`), numpy (and its ``numpy.libs``), the kit's allowed modules
  (:data:`dtscal_lib.grading.loader.KIT_ALLOWED`) and the harness;
* exactly the shared libraries those load (their ELF dependencies as ``ldd`` resolves them),
  every symbolic link on the way kept (Debian's ``/etc/alternatives`` for BLAS); no other file of
  ``/usr``, ``/etc`` or ``/opt``, no home, no kit checkout, no ``.git``, no ``grading/``, no class
  folder, no other submission, no host socket;
* a private working tmpfs of :data:`TMPFS_MB` (the submission's only writable place; the root is
  remounted read-only), a fresh ``/proc`` of its own PID namespace, a minimal ``/dev``, no network
  (``--unshare-net``), its own user namespace with a uid per concurrent submission
  (:class:`_Slots`, shared by this user's graders through lock files in a folder of its own);
* seccomp filters (:mod:`.seccomp`): the first loaded by bwrap itself.

One sandbox per submission (all its checks in it, each in a fresh worker process forked from a
trusted zygote that runs no student code): starting bwrap and Python costs tens of ms, once per
submission instead of once per check (``benchmarks/bench_grade.py`` prints the cost), while each
check still runs in its own process with its own limits.

The answers come back as one length-prefixed frame per check over the harness's stdout, with
hard caps on header size, number of arrays and bytes *before* anything is decoded; each array is
a plain ``.npy`` of numbers (an object array, i.e. a pickle, is refused unread: :func:`_npy`), each
at most once, over the frame's own bytes; each check's answers are judged and dropped before the
next check's arrive. The sandbox writes no file
the grader reads. Only values come back, never verdicts: the grader compares them with the truth
it alone holds (:mod:`.checks`).

Where bubblewrap cannot run (no user namespaces, as in some containers), ``dtscal grade``
refuses unless the instructor accepts the risk (:mod:`.command`, :mod:`.preflight`); then the
same harness runs as a bare process in a session of its own, and :func:`barriers` says which
barriers hold (and which do not), for ``results.json`` and the command line. A sandbox that
fails to start or dies on the grader's side is retried (:data:`RETRIES`) with the checks not yet
answered; then :class:`GraderError` says "not graded: grader error, rerun" and carries the
answers already given.
"""

from __future__ import annotations

import atexit
import fcntl
import io
import json
import os
import pickle
import select
import shutil
import signal
import stat
import struct
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import seccomp
from .errors import GRADER_ERROR, GraderError
from .harness import ANSWER_MARK, MAX_ANSWER_BYTES, MAX_BLOBS, MAX_HEADER_BYTES, CheckJob, SandboxJob, load_budget

__all__ = ["CheckJob", "SandboxJob", "Call", "CheckRun", "SandboxRun", "GraderError", "GRADER_ERROR", "run_calls",
           "barriers"]

#: default limits, per check (wall-clock and CPU seconds) and per submission (memory)
WALL_S, CPU_S, MEM_MB, OUTPUT_CHARS = 10.0, 8, 2048, 2000
#: bounds of the limits an instructor may set (``dtscal grade --wall/--cpu/--mem``):
#: the reference solutions' slowest check takes well under 1 s, so 600 s per check is already
#: generous; a worker of the harness maps about 600 MB of address space (numpy's OpenBLAS
#: reserves most of it) before a submission allocates anything: 1024 MB leaves room
#: for the 640x480 float maps of notebook 04.
MAX_WALL_S, MAX_CPU_S, MIN_MEM_MB = 600.0, 600, 1024
#: the submission's working tmpfs: the notebooks' exercises write no file at all
TMPFS_MB = 64
#: a sandbox that fails on the grader's side is started again this many times, after a pause
#: growing by this many seconds each time
RETRIES, RETRY_PAUSE_S = 3, 0.2


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


#: "bubblewrap" (default when bwrap runs here), "bare" (the harness without bubblewrap: what a
#: machine without user namespaces gets; benchmarks compare the two)
MODE: str | None = None
#: time allowed for loading the submission (the harness's first try; :func:`.harness.load_budget`
#: bounds all tries), and what the grader allows on top for starting the sandbox and numpy
LOAD_WALL_S, LOAD_MARGIN_S = 30.0, 15.0
MAX_ARRAY_BYTES = MAX_ANSWER_BYTES


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
    #: forbidden names (OpenCV's, the kit's solving modules) the call reached for
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
        try:
            return f"the process was ended by signal {signal.Signals(sig).name}"
        except ValueError:
            return f"the process was ended by signal {sig}"
    code = status.split()[1] if " " in status else status
    return f"the function ended the process (os._exit / exit status {code}) before returning"


class _Opaque:
    """An answer that is not numbers (e.g. an object whose ``__eq__`` always says True)."""

    def __init__(self, type_name: str):
        self.type_name = type_name

    def __repr__(self):
        return f"<a {self.type_name} object>"


# --------------------------------------------------------------------------- decoding (untrusted bytes)


class _Unreadable(Exception):
    pass


def split_frame(data: bytes, offset: int = 0) -> tuple[dict, list[memoryview], int]:
    """One frame of ``data`` at ``offset``: (header, blobs, end). Caps hold before decoding."""
    view = memoryview(data)
    if len(data) - offset < 4:
        raise _Unreadable("short frame")
    (n,) = struct.unpack_from(">I", data, offset)
    if n > MAX_HEADER_BYTES or offset + 4 + n > len(data):
        raise _Unreadable("header too large")
    try:
        header = json.loads(bytes(view[offset + 4: offset + 4 + n]))
    except ValueError:
        raise _Unreadable("header not JSON") from None
    sizes = header.get("blobs") if isinstance(header, dict) else None
    if not isinstance(sizes, list) or len(sizes) > MAX_BLOBS or \
            not all(isinstance(s, int) and s >= 0 for s in sizes) or sum(sizes) > MAX_ANSWER_BYTES:
        raise _Unreadable("too many or too large arrays")
    pos, blobs = offset + 4 + n, []
    for s in sizes:
        if pos + s > len(data):
            raise _Unreadable("truncated")
        blobs.append(view[pos: pos + s])
        pos += s
    return header, blobs, pos


def _npy(blob: memoryview) -> np.ndarray:
    """A plain ``.npy`` (numpy's format 1.0 or 2.0) as an array over ``blob``'s own bytes, no copy:
    numbers only; an object array (a pickle, which would run code here) is refused, never loaded."""
    head = io.BytesIO(bytes(blob[:min(len(blob), 65536 + 16)]))
    version = np.lib.format.read_magic(head)
    if version == (1, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_1_0(head)
    elif version == (2, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_2_0(head)
    else:
        raise ValueError(f"npy format {version}")
    if dtype.hasobject or dtype.kind not in "biuf":
        raise ValueError("not an array of numbers (a pickle?)")
    count = int(np.prod(shape, dtype=np.int64))
    if head.tell() + count * dtype.itemsize != len(blob):
        raise ValueError("size does not match the header")
    arr = np.frombuffer(blob, dtype=dtype, count=count, offset=head.tell())
    return arr.reshape(shape, order="F" if fortran else "C")


class _Decoder:
    """Arrays of one answer frame: each blob decoded at most once (no fan-out of one array)."""

    def __init__(self, blobs: list):
        self.blobs, self.used = blobs, set()

    def value(self, desc, depth: int = 0):
        if not isinstance(desc, dict):
            return None, ""
        kind = desc.get("kind")
        if kind == "tuple" and depth == 0:
            items = desc.get("items")
            return ((tuple(self.value(d, 1)[0] for d in items[:4]) if isinstance(items, list) else None),
                    str(desc.get("note", ""))[:120])
        if kind == "object":
            return _Opaque(str(desc.get("type", "?"))[:60]), ""
        if kind == "array":
            i = desc.get("blob")
            if not isinstance(i, int) or not 0 <= i < len(self.blobs) or i in self.used:
                return None, "unreadable answer"
            self.used.add(i)
            try:
                arr = _npy(self.blobs[i])
            except Exception:  # noqa: BLE001
                return None, "unreadable answer"
            if type(arr) is not np.ndarray or arr.dtype.kind not in "biuf":
                return None, "unreadable answer"
            return arr, str(desc.get("note", ""))[:120]
        return None, ""


def last_answer(data: bytes) -> memoryview | None:
    """The answer frame that closes a worker's output (length + mark at the very end), or None."""
    if len(data) < 16 or data[-8:] != ANSWER_MARK:
        return None
    (n,) = struct.unpack(">Q", data[-16:-8])
    if n > len(data) - 16:
        return None
    return memoryview(data)[len(data) - 16 - n: len(data) - 16]


def decode_answers(data: bytes) -> list[Call] | None:
    """The calls of one worker's answer frame, or None when it is not a well-formed frame.

    Never raises: whatever the bytes hold (a JSON header nested 200,000 levels deep, which makes
    the parser raise RecursionError; a 401-digit number, OverflowError as a float; a pickled
    array, refused by ``allow_pickle=False``), a malformed frame is that check's unreadable
    answer, the student's, never an error of the grader's."""
    try:
        return _decode_answers(data)
    except Exception:  # noqa: BLE001 - untrusted bytes: any failure to decode is an unreadable answer
        return None


def _decode_answers(data: bytes) -> list[Call] | None:
    try:
        header, blobs, end = split_frame(data)
    except _Unreadable:
        return None
    entries = header.get("calls")
    if end != len(data) or not isinstance(entries, list) or len(entries) > 1000:
        return None
    dec = _Decoder(blobs)
    calls = []
    for e in entries:
        if not isinstance(e, dict):
            return None
        c = Call(ok=bool(e.get("ok")), error=str(e.get("error", ""))[:400],
                 not_implemented=bool(e.get("not_implemented")), stdout=str(e.get("stdout", ""))[:4000])
        if c.ok:
            c.value, c.note = dec.value(e.get("value"))
        try:
            c.seconds = float(e.get("time", 0.0))
        except (TypeError, ValueError):
            pass
        honesty = e.get("honesty")
        if isinstance(honesty, list):
            c.honesty = [str(h)[:80] for h in honesty[:10]]
        after = e.get("args_after")
        if isinstance(after, list):
            c.args_after = [dec.value(a, 1)[0] if a else None for a in after[:16]]
        calls.append(c)
    return calls


# --------------------------------------------------------------------------- what the sandbox holds


def _kit_dir() -> Path:
    return Path(__file__).resolve().parents[1]


_LIB_LOCK = threading.Lock()
_LIB: dict = {}


def sandbox_lib() -> Path:
    """A folder (0755, this grader's own) with the harness, the seccomp module and the kit's
    allowed modules: the only files of the kit the sandbox sees. Made once per grader process."""
    from .loader import KIT_ALLOWED

    with _LIB_LOCK:
        if "dir" in _LIB:
            return _LIB["dir"]
        d = Path(tempfile.mkdtemp(prefix="dtscal-sandbox-lib-"))
        atexit.register(shutil.rmtree, d, True)
        here = Path(__file__).parent
        for name in ("harness.py", "seccomp.py"):
            shutil.copyfile(here / name, d / name)
        (d / "empty").mkdir()
        kit = d / "kit" / "dtscal_lib"
        kit.mkdir(parents=True)
        for mod in KIT_ALLOWED:  # dtscal_lib.duckietown -> dtscal_lib/duckietown.py
            rel = mod.split(".", 1)[1].replace(".", "/") + ".py"
            (kit / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(_kit_dir() / rel, kit / rel)
        for p in [d, *d.rglob("*")]:
            os.chmod(p, 0o755 if p.is_dir() else 0o644)
        _LIB["dir"] = d
        return d


#: the interpreter the sandbox runs (default: this grader's own, without its virtualenv) and the
#: folder holding numpy (default: this grader's numpy): settings for a grader whose Python lies
#: where the sandbox's user cannot read it (the tests' unprivileged user)
INTERPRETER: str | None = None
NUMPY_SITE: str | None = None


_MANIFESTS: dict = {}
_MANIFEST_LOCK = threading.Lock()

#: folders of the standard library no exercise imports, left out (laid over with an empty folder):
#: the base interpreter's own packages (an OpenCV?), CPython's test suite, IDLE, Tk, pip's wheels
STDLIB_LEFT_OUT = ("site-packages", "dist-packages", "test", "idlelib", "tkinter", "turtledemo", "ensurepip")
#: extension modules of the standard library left out: what they load is no exercise's (Tk and
#: X11, OpenSSL, ncurses, readline, SQLite, dbm, NIS, crypt); with them, 42 more libraries
#: (``ldd lib-dynload/*.so`` on CPython 3.11) would enter the sandbox
DYNLOAD_LEFT_OUT = ("_tkinter", "_ssl", "_hashlib", "_curses", "_curses_panel", "readline", "_sqlite3", "_dbm",
                    "_gdbm", "nis", "_crypt")


@dataclass
class Manifest:
    """Everything the sandbox's filesystem holds besides ``/proc``, ``/dev`` and its working tmpfs,
    read-only, as ``{path inside: path on the host}``: folders bound whole (``trees``, with the
    sub-folders ``covered`` by an empty one), single files, and symbolic links (``{path: target}``,
    e.g. Debian's ``libblas.so.3`` -> ``/etc/alternatives/...`` -> ``blas/libblas.so.3``).

    ``interpreter`` is the Python the sandbox runs; ``dynload`` the folder of the standard
    library's extension modules, of which only ``dynload_kept`` are there."""

    interpreter: str = ""
    trees: dict = field(default_factory=dict)
    covered: list = field(default_factory=list)
    dynload: str = ""
    dynload_kept: list = field(default_factory=list)
    files: dict = field(default_factory=dict)
    links: dict = field(default_factory=dict)
    lib_dirs: list = field(default_factory=list)

    def entries(self) -> set[str]:
        """Every file and link inside (no folders), as the sandbox lists them."""
        out = set(self.files) | set(self.links)
        for inside, host in self.trees.items():
            for d, dirs, files in os.walk(host):
                rel = os.path.relpath(d, host)
                here = os.path.normpath(os.path.join(inside, rel))
                if here in self.covered or here == self.dynload:
                    dirs[:] = []
                    continue
                out.update(os.path.join(here, n) for n in files)
                out.update(os.path.join(here, n) for n in dirs if os.path.islink(os.path.join(d, n)))
        out.update(os.path.join(self.dynload, n) for n in self.dynload_kept)
        return out


def manifest() -> Manifest:
    """The sandbox's files for this grader's interpreter and numpy (built once per setting)."""
    key = (INTERPRETER, NUMPY_SITE)
    with _MANIFEST_LOCK:
        if key not in _MANIFESTS:
            _MANIFESTS[key] = _build_manifest()
        return _MANIFESTS[key]


def _build_manifest() -> Manifest:
    """The interpreter, its standard library (minus :data:`STDLIB_LEFT_OUT` and
    :data:`DYNLOAD_LEFT_OUT`), numpy (+ ``numpy.libs``), the harness and the kit's allowed
    modules, and exactly the shared libraries those load: their ELF dependencies, as the dynamic
    loader resolves them (``ldd``), each link of the way kept."""
    import sysconfig

    if INTERPRETER:
        exe = os.path.realpath(INTERPRETER)
        out = subprocess.run([exe, "-I", "-S", "-c", "import sysconfig; print(sysconfig.get_paths()['stdlib'])"],
                             capture_output=True, text=True, check=True)
        stdlib = out.stdout.strip()
    else:
        exe, stdlib = os.path.realpath(sys.executable), sysconfig.get_paths()["stdlib"]
    stdlib = os.path.realpath(stdlib)
    site = NUMPY_SITE or os.path.dirname(os.path.dirname(os.path.realpath(np.__file__)))
    m = Manifest(interpreter=exe)
    m.files[exe] = exe
    m.trees[stdlib] = stdlib
    m.covered = [os.path.join(stdlib, d) for d in STDLIB_LEFT_OUT if os.path.isdir(os.path.join(stdlib, d))]
    m.dynload = os.path.join(stdlib, "lib-dynload")
    elves = [exe]
    if os.path.isdir(m.dynload):
        m.dynload_kept = sorted(n for n in os.listdir(m.dynload) if n.split(".")[0] not in DYNLOAD_LEFT_OUT
                                and os.path.isfile(os.path.join(m.dynload, n)))
        elves += [os.path.join(m.dynload, n) for n in m.dynload_kept if n.endswith(".so")]
    for n in ("numpy", "numpy.libs"):
        d = os.path.join(site, n)
        if os.path.isdir(d):
            m.trees[f"/sandbox/site/{n}"] = d
            elves += [os.path.join(r, f) for r, _, fs in os.walk(d) for f in fs if ".so" in f]
    m.trees["/sandbox/harness"] = str(sandbox_lib())
    hosts = [os.path.realpath(h) for h in m.trees.values()]
    dirs = set()
    for lib in _elf_needs(elves):
        real = _resolve(lib, m.links)
        if not any(real == h or real.startswith(h + os.sep) for h in hosts):  # numpy.libs: there already
            m.files[real] = real
            dirs.add(os.path.dirname(lib))
    m.lib_dirs = sorted(dirs)
    return m


def _elf_needs(paths: list[str]) -> list[str]:
    """The shared libraries ``paths`` load, transitively, as the dynamic loader finds them (``ldd``,
    glibc's, which prints the whole closure per file; the files are the kit's own interpreter and
    numpy, never a submission's)."""
    ldd = shutil.which("ldd") or "/usr/bin/ldd"
    found: list[str] = []
    for i in range(0, len(paths), 200):
        run = subprocess.run([ldd, *paths[i:i + 200]], capture_output=True, text=True, env={"LC_ALL": "C"})
        for line in run.stdout.splitlines():
            line = line.strip()
            if "=>" in line:
                path = line.split("=>", 1)[1].strip().split(" (")[0].strip()
            elif line.startswith("/") and " (0x" in line:
                path = line.split(" (")[0]
            else:
                continue
            if path.startswith("/") and path not in found:
                found.append(path)
    return found


def _resolve(path: str, links: dict, depth: int = 0) -> str:
    """``path`` with every symbolic link on the way resolved, each recorded in ``links``."""
    if depth > 40:
        raise OSError(f"too many levels of symbolic links: {path}")
    cur = "/"
    for part in Path(path).parts[1:]:
        nxt = os.path.join(cur, part)
        if os.path.islink(nxt):
            target = os.readlink(nxt)
            links[nxt] = target
            nxt = _resolve(os.path.normpath(os.path.join(cur, target)), links, depth + 1)
        cur = nxt
    return cur


SANDBOX_UID_BASE = 64000
SANDBOX_HOME = "/tmp"


def bwrap_argv(slot: int, seccomp_fd: int | None) -> list[str]:
    """bubblewrap's command line for one submission in uid slot ``slot``: a new root holding
    :func:`manifest` read-only and nothing else (``/proc`` and ``/dev`` of its own, a tmpfs)."""
    m = manifest()
    uid = SANDBOX_UID_BASE + slot
    empty = str(sandbox_lib() / "empty")  # an empty read-only folder laid over what is left out
    argv = ["bwrap", "--unshare-all", "--unshare-user", "--uid", str(uid), "--gid", str(uid),
            "--die-with-parent", "--new-session", "--cap-drop", "ALL", "--clearenv",
            "--setenv", "PATH", "/nonexistent", "--setenv", "LANG", "C.UTF-8", "--setenv", "OPENBLAS_NUM_THREADS", "1",
            "--setenv", "LD_LIBRARY_PATH", ":".join(m.lib_dirs)]
    for inside, host in m.trees.items():
        argv += ["--ro-bind", host, inside]
    for c in m.covered:
        argv += ["--ro-bind", empty, c]
    if m.dynload_kept:  # the extension modules kept, alone in a folder of their own
        argv += ["--tmpfs", m.dynload]
        for n in m.dynload_kept:
            argv += ["--ro-bind", os.path.join(m.dynload, n), os.path.join(m.dynload, n)]
        argv += ["--remount-ro", m.dynload]
    for inside, host in m.files.items():
        argv += ["--ro-bind", host, inside]
    for link, target in sorted(m.links.items()):
        argv += (["--dir", os.path.dirname(link)] if os.path.dirname(link) != "/" else []) + \
            ["--symlink", target, link]
    argv += ["--proc", "/proc", "--dev", "/dev",
             "--size", str(TMPFS_MB * 2 ** 20), "--tmpfs", SANDBOX_HOME, "--chdir", SANDBOX_HOME,
             "--setenv", "HOME", SANDBOX_HOME, "--remount-ro", "/"]
    if seccomp_fd is not None:
        argv += ["--seccomp", str(seccomp_fd)]
    # -I ignores PYTHONPATH: the harness sets sys.path itself (see _entry)
    return argv + ["--", m.interpreter, "-I", "-S", "-c",
                   _ENTRY.format(harness="/sandbox/harness", site="/sandbox/site")]


_ENTRY = ("import sys; sys.path[:0] = [{harness!r}, {site!r}]; import runpy; "
          "runpy.run_path({harness!r} + '/harness.py', run_name='__main__')")


def _bare_argv() -> list[str]:
    m = manifest()
    site = os.path.dirname(m.trees["/sandbox/site/numpy"])
    return [m.interpreter, "-I", "-S", "-c", _ENTRY.format(harness=str(sandbox_lib()), site=site)]


def probe_argv(code: str) -> list[str]:
    """The command that runs ``code`` with the interpreter and numpy a submission gets (inside bubblewrap,
    or bare where there is none), without the harness: for checks at the grader's start."""
    if mode() == "bare":
        m = manifest()
        site = os.path.dirname(m.trees["/sandbox/site/numpy"])
        return [m.interpreter, "-I", "-S", "-c", f"import sys; sys.path[:0] = [{site!r}]; {code}"]
    argv = bwrap_argv(0, None)
    i = argv.index("--")
    return argv[:i + 1] + [argv[i + 1], "-I", "-S", "-c", f"import sys; sys.path[:0] = ['/sandbox/site']; {code}"]


_PROBE: dict = {}


def bwrap_available() -> tuple[bool, str]:
    """Does bubblewrap run here (as this user)? (yes/no, why not). Probed once."""
    with _LIB_LOCK:
        if "result" in _PROBE:
            return _PROBE["result"]
    if shutil.which("bwrap") is None:
        result = (False, "bubblewrap (bwrap) is not installed: run scripts/install-sandbox.sh")
    else:
        argv = bwrap_argv(0, None)
        i = argv.index("--")
        try:
            run = subprocess.run(argv[:i + 1] + [argv[i + 1], "-I", "-S", "-c", "pass"], capture_output=True,
                                 timeout=60, stdin=subprocess.DEVNULL)
            result = (run.returncode == 0, run.stderr.decode(errors="replace").strip()[-300:])
        except (OSError, subprocess.SubprocessError) as exc:
            result = (False, str(exc))
    with _LIB_LOCK:
        _PROBE["result"] = result
    return result


def mode() -> str:
    if MODE:
        return MODE
    return "bubblewrap" if bwrap_available()[0] else "bare"


def barriers() -> dict:
    """What holds around a submission on this machine, in words (results.json, command line):
    only barriers that hold; without bubblewrap, ``not_held`` names those missing."""
    m = mode()
    sec = ("seccomp: no exec, no ptrace/mount/unshare/bpf/keyctl/memfd_create/io_uring/sockets, no fcntl/ioctl "
           "that names a process to signal; the student's code can start no process or thread and signal only "
           "itself" if seccomp.supported() else None)
    out = {"mode": m, **({"seccomp": sec} if sec else {}),
           "memory": "address space capped per process (--mem); the student's code runs in one process that "
                     "can start no other, so the cap bounds the submission",
           "answers": "values only, over a capped length-prefixed pipe; judged outside the sandbox"}
    if m == "bubblewrap":
        out.update(filesystem="bubblewrap: only its manifest (the interpreter, its standard library, numpy, the "
                              "kit's allowed modules and the libraries these load), read-only; a private "
                              f"{TMPFS_MB} MB tmpfs; no kit checkout, grading material, home, /etc or other "
                              "submissions",
                   network="network namespace: no network, no host socket",
                   processes="PID namespace: the submission sees and signals only its own processes, all die "
                             "with it",
                   user="user namespace: a uid per concurrent submission (lock files of the grader's own user)")
        return out
    why = bwrap_available()[1] if MODE is None else "bubblewrap turned off"
    if sec:
        out.update(network="sockets refused by seccomp",
                   processes="a session and process group of its own; seccomp: no new process, signals only to "
                             "itself; the grader's process is undumpable (no /proc/PID/mem of it)")
    out["not_held"] = [f"filesystem ({why}): the student's code reads and writes what the grader's user can, the "
                       "hidden cases and the other submissions included; the import rule stops OpenCV and the kit's "
                       "solvers imported by name, not loaded by path (importlib.util.spec_from_file_location)",
                       "PID namespace", "network namespace", "user namespace"]
    if not sec:
        out["not_held"].append("seccomp (no system-call table for this architecture): processes, signals, sockets")
    return out


# --------------------------------------------------------------------------- uids


class _Slots:
    """A uid slot per concurrent submission, on this machine: a lock file per slot (flock),
    so two graders of one user started at once never run submissions under the same uid.

    The lock files lie in a folder only the grader's user can write (:meth:`directory`): in a
    folder that others can write (the world-writable temp folder), any local user could create and
    hold every slot file first, and every student of the grader would be "grader error"."""

    def __init__(self):
        self.lock = threading.Lock()

    @staticmethod
    def directory() -> Path:
        """``$XDG_RUNTIME_DIR/dtscal-grade-slots``, else ``~/.cache/dtscal-grade-slots``, else
        ``$TMPDIR/dtscal-grade-slots-UID``: the first that is a real folder of this user's that no
        one else may write (0700); else a private folder of this grader alone."""
        uid = os.getuid()
        places = [Path(os.environ["XDG_RUNTIME_DIR"]) / "dtscal-grade-slots"] if os.environ.get(
            "XDG_RUNTIME_DIR") else []
        places += [Path(os.path.expanduser("~")) / ".cache" / "dtscal-grade-slots",
                   Path(tempfile.gettempdir()) / f"dtscal-grade-slots-{uid}"]
        for d in places:
            try:
                d.mkdir(mode=0o700, parents=True, exist_ok=True)
                st = os.lstat(d)
            except OSError:
                continue
            if stat.S_ISDIR(st.st_mode) and st.st_uid == uid and not st.st_mode & 0o022:
                return d
        with _LIB_LOCK:
            if "slots" not in _LIB:
                _LIB["slots"] = Path(tempfile.mkdtemp(prefix="dtscal-grade-slots-"))
                atexit.register(shutil.rmtree, _LIB["slots"], True)
            return _LIB["slots"]

    def take(self) -> tuple[int, int]:
        d = self.directory()
        for k in range(4096):
            try:
                fd = os.open(d / f"slot{k}", os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o600)
            except OSError:
                continue
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                return k, fd
            except OSError:
                os.close(fd)
        raise GraderError("no free uid slot for a sandbox")

    @staticmethod
    def give(fd: int) -> None:
        os.close(fd)  # releases the flock


_SLOTS = _Slots()


# --------------------------------------------------------------------------- running


def _as_job(c) -> CheckJob:
    if isinstance(c, CheckJob):
        return c
    return CheckJob(id=int(c["id"]), calls=list(c["calls"]), wall=float(c["wall"]), cpu=int(c["cpu"]),
                    substitute=list(c.get("substitute", ())))


def run_calls(statements: list[tuple[str, int]], checks: list, *, mem_mb: int = MEM_MB,
              output_chars: int = OUTPUT_CHARS, workdir_files: dict | None = None, judge=None) -> SandboxRun:
    """Run ``checks`` (:class:`CheckJob`, or dicts with the same keys) on the submission.

    Parameters
    ----------
    statements : the submission's import/def statements ``(source, first line)``
    checks : inputs only; the answers are judged by the caller
    workdir_files : ``{name: bytes}`` written into the working folder
    judge : ``judge(check id, CheckRun)``, called as each check's answer arrives; the answer is
        then dropped (``run.checks`` keeps the check's id with no values), so the grader holds
        one check's answers at a time, never a whole submission's

    Returns
    -------
    SandboxRun
        A :class:`CheckRun` for every check id, with ``failure`` set for checks that did not
        finish; ``load_errors`` lists statements that failed or killed the process.

    Raises
    ------
    GraderError
        when the sandbox failed on the grader's side :data:`RETRIES` times ("not graded: grader
        error, rerun"; never the student's zero); its ``run`` holds the checks answered before
        the failure, which the caller keeps (only the unanswered ones are the grader's failure).
    """
    from .loader import CV2_DENY, KIT_ALLOWED

    jobs = [_as_job(c) for c in checks]
    run = SandboxRun()
    _answers_given_back()
    m = mode()
    if m != "bubblewrap":
        _undumpable()
    run.notes.update(barriers())
    run.notes["pid_namespace"] = m == "bubblewrap"
    run.notes["survivors"] = 0
    skip: list[int] = []
    todo = list(jobs)
    errors = []
    for attempt in range(RETRIES):
        if not todo:
            break
        job = SandboxJob(statements=list(statements), checks=todo, skip=list(skip), mem_mb=int(mem_mb),
                         output_limit=int(output_chars), load_wall=LOAD_WALL_S, workdir=SANDBOX_HOME
                         if m == "bubblewrap" else "", workdir_files=dict(workdir_files or {}),
                         cv2_deny=sorted(CV2_DENY), kit_allowed=list(KIT_ALLOWED),
                         kit_dir="/sandbox/harness/kit" if m == "bubblewrap" else str(sandbox_lib() / "kit"), mode=m)
        try:
            _one_sandbox(job, run, skip, judge)
        except GraderError as exc:
            errors.append(str(exc))
            time.sleep(RETRY_PAUSE_S * (attempt + 1))
        todo = [c for c in jobs if c.id not in run.checks]
    if todo:  # the checks answered before the failure travel with it (the caller keeps them)
        failure = GraderError(f"{GRADER_ERROR} ({'; '.join(errors)[-600:]})")
        failure.run = run  # type: ignore[attr-defined]
        raise failure
    return run


_MALLOC: dict = {}


def _answers_given_back() -> None:
    """Once per grader: large blocks (answers, their judging) straight from and back to the system
    (glibc's ``mallopt(M_MMAP_THRESHOLD, 1 MiB)``, which also stops glibc raising the threshold
    to the size of each freed block, mallopt(3)). Without it a class of answers just under the cap
    left the grader at 233 MB against the solutions' 113 MB (freed blocks kept in the heap); with
    it 171 MB (benchmarks/bench_grade.py)."""
    with _LIB_LOCK:
        if _MALLOC:
            return
        _MALLOC["done"] = True
    try:
        import ctypes

        ctypes.CDLL(None).mallopt(-3, 2 ** 20)  # M_MMAP_THRESHOLD (malloc.h)
    except (OSError, AttributeError):  # not glibc: its own allocator's behaviour
        pass


def _undumpable() -> None:
    """Without bubblewrap the student's code runs as the grader's user: make the grader's process
    undumpable (``PR_SET_DUMPABLE`` 0), so that no process of that user opens its ``/proc/PID/mem``
    or ``fd/`` (proc(5); the kernel's ptrace access check)."""
    import ctypes

    ctypes.CDLL(None, use_errno=True).prctl(4, 0, 0, 0, 0)


def _one_sandbox(job: SandboxJob, run: SandboxRun, skip: list[int], judge=None) -> None:
    m = job.mode
    slot, slot_fd = _SLOTS.take()
    workdir = None
    sec_r = None
    try:
        if m == "bubblewrap":
            if seccomp.supported():
                sec_r, sec_w = os.pipe()
                os.write(sec_w, seccomp.sandbox_filter())
                os.close(sec_w)
            argv = bwrap_argv(slot, sec_r)
            env = {}
        else:
            workdir = tempfile.mkdtemp(prefix="dtscal-grade-")
            job.workdir = workdir
            argv = _bare_argv()
            env = {"LANG": "C.UTF-8", "PATH": "/nonexistent", "OPENBLAS_NUM_THREADS": "1"}
        run.notes["uid"] = SANDBOX_UID_BASE + slot if m == "bubblewrap" else os.getuid()
        try:
            proc = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                    pass_fds=(sec_r,) if sec_r is not None else (), env=env, cwd="/",
                                    start_new_session=True)
        except OSError as exc:
            raise GraderError(f"the sandbox did not start: {exc}") from None
        finally:
            if sec_r is not None:
                os.close(sec_r)
                sec_r = None
        err: list[bytes] = []
        drainer = threading.Thread(target=_drain, args=(proc.stderr, 8000, err), daemon=True)
        drainer.start()
        try:
            _converse(proc, job, run, skip, err, judge)
        finally:
            procs = _descendants(proc.pid)  # the sandbox's processes, looked for again once it is gone
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except OSError:
                pass
            proc.wait()
            run.notes["survivors"] = run.notes.get("survivors", 0) + _survivors(procs)
            drainer.join(timeout=2)
            for f in (proc.stdin, proc.stdout, proc.stderr):
                try:
                    f.close()
                except OSError:
                    pass
    finally:
        if sec_r is not None:
            os.close(sec_r)
        if workdir:
            shutil.rmtree(workdir, ignore_errors=True)
        _SLOTS.give(slot_fd)


def _stat(pid: int) -> list[str] | None:
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return text[text.rindex(")") + 2:].split()


def _descendants(root: int) -> dict[int, str]:
    """``{pid: start time}`` of ``root`` and every process below it."""
    parent = {}
    for d in os.listdir("/proc"):
        if d.isdigit():
            f = _stat(int(d))
            if f is not None and f[0] not in "ZX":
                parent[int(d)] = (int(f[1]), f[19])
    found, todo = {}, [root]
    while todo:
        p = todo.pop()
        if p in parent and p not in found:
            found[p] = parent[p][1]
            todo += [c for c, (pp, _) in parent.items() if pp == p]
    return found


def _survivors(procs: dict[int, str], rounds: int = 50) -> int:
    """How many of ``procs`` still live (same pid, same start time) after ``rounds`` SIGKILLs."""
    alive = []
    for _ in range(rounds):
        alive = [p for p, start in procs.items() if (f := _stat(p)) is not None and f[19] == start and f[0] not in "ZX"]
        if not alive:
            return 0
        for p in alive:
            try:
                os.kill(p, signal.SIGKILL)
            except OSError:
                pass
        time.sleep(0.01)
    return len(alive)


def _drain(stream, keep: int, sink: list) -> None:
    size = 0
    for chunk in iter(lambda: stream.read(65536), b""):
        if size < keep:
            sink.append(chunk[: keep - size])
        size += len(chunk)


def _converse(proc, job: SandboxJob, run: SandboxRun, skip: list[int], err: list, judge=None) -> None:
    data = pickle.dumps(job, protocol=pickle.HIGHEST_PROTOCOL)
    try:
        proc.stdin.write(struct.pack(">Q", len(data)) + data)
        proc.stdin.close()
    except OSError as exc:
        raise GraderError(f"the sandbox did not take its job: {exc}; {b''.join(err).decode(errors='replace')}") \
            from None
    by_id = {c.id: c for c in job.checks}
    fd = proc.stdout.fileno()
    buf = bytearray()
    # the harness answers "ready" within load_budget (it skips statements that load too slowly)
    deadline = time.monotonic() + load_budget(job.load_wall) + LOAD_MARGIN_S
    state = {"hello": False, "deadline": None}
    while True:
        frame = _next_frame(fd, buf, deadline)
        if frame is None:
            proc.poll()
            why = "stopped answering" if time.monotonic() > deadline else "ended"
            raise GraderError(f"the sandbox {why} (exit status {proc.returncode}): "
                              + b"".join(err).decode(errors="replace")[-1500:].strip())
        header, blobs = frame
        del frame
        try:  # a large answer's turn (see BIG_FRAME_BYTES) ends with its frame, whatever happens
            if _on_frame(header, blobs, job, run, skip, judge, by_id, state):
                return
        finally:
            del blobs
            if header.get("_big"):
                _BIG_FRAME.release()
        deadline = state["deadline"] or deadline
        state["deadline"] = None


def _on_frame(header: dict, blobs: list, job: SandboxJob, run: SandboxRun, skip: list[int], judge, by_id: dict,
              state: dict) -> bool:
    """Take one frame of the harness; True once it has finished. A new deadline goes to ``state``."""
    ev = header.get("event")
    if ev == "hello":
        state["hello"] = True
        run.notes.update({str(k): str(v)[:300] for k, v in dict(header.get("notes", {})).items()})
    elif not state["hello"]:
        raise GraderError("the sandbox broke its protocol")
    elif ev == "load_error":
        k = header.get("k")
        if isinstance(k, int) and 0 <= k < len(job.statements):
            run.load_errors.append((k, str(header.get("error", ""))[:400]))
            if k not in skip:
                skip.append(k)
    elif ev == "ready":
        state["deadline"] = time.monotonic() + (job.checks[0].wall + 10 if job.checks else 10)
    elif ev == "check":
        cid = header.get("id")
        if cid not in by_id or cid in run.checks:
            raise GraderError("the sandbox broke its protocol")
        c = by_id[cid]
        status = str(header.get("status", ""))[:40]
        answer = last_answer(blobs[0]) if status == "exit 0" and len(blobs) == 1 else None
        calls = decode_answers(answer) if answer is not None else None
        del answer, blobs[:]
        cr = CheckRun(failure=_describe(status, c.wall, c.cpu, job.mem_mb)) if calls is None else CheckRun(calls=calls)
        del calls
        if judge is not None:  # judged now, then dropped: one check's answers at a time
            judge(cid, cr)
            cr = CheckRun(failure=cr.failure)
        run.checks[cid] = cr
        nxt = next((x for x in job.checks if x.id not in run.checks), None)
        state["deadline"] = time.monotonic() + (nxt.wall + 10 if nxt else 10)
    elif ev == "finished":
        return True
    return False


def _next_frame(fd: int, buf: bytearray, deadline: float):
    """Read one frame from the harness (the trusted zygote: still capped). Once its header is read,
    the frame's bytes go straight into one buffer of the frame's size (no copy of a large answer)."""
    need = None
    while True:
        if len(buf) >= 4 and need is None:
            (n,) = struct.unpack_from(">I", buf, 0)
            if n > MAX_HEADER_BYTES:
                return None
            if len(buf) >= 4 + n:
                try:
                    header = json.loads(bytes(buf[4: 4 + n]))
                    sizes = header["blobs"]
                    if not isinstance(header, dict) or len(sizes) > 1 or \
                            not all(isinstance(s, int) and 0 <= s <= MAX_ANSWER_BYTES + MAX_HEADER_BYTES + 16
                                    for s in sizes):
                        return None
                except (ValueError, KeyError, TypeError, RecursionError, OverflowError):
                    return None
                need = 4 + n + sum(sizes)
                if need > BIG_FRAME_BYTES:  # one large answer in this grader at a time, whatever --jobs
                    if not _BIG_FRAME.acquire(timeout=max(0.0, deadline - time.monotonic())):
                        return None
                    header["_big"] = True
                if len(buf) < need:  # the rest is read into the frame's own buffer
                    whole = bytearray(need)
                    whole[:len(buf)] = buf
                    got = len(buf)
                    del buf[:]
                    if not _read_into(fd, memoryview(whole)[got:], deadline):
                        if header.get("_big"):
                            _BIG_FRAME.release()
                        return None
                    return _cut(header, whole, 4 + n, sizes)
        if need is not None and len(buf) >= need:
            whole = bytearray(buf[:need])
            del buf[:need]
            return _cut(header, whole, 4 + n, sizes)
        left = deadline - time.monotonic()
        if left <= 0 or not select.select([fd], [], [], left)[0]:
            return None
        chunk = os.read(fd, 1 << 20)
        if not chunk:
            return None
        buf += chunk


#: a frame larger than this (the answers of one check) is read, decoded and judged by one thread of
#: the grader at a time (:data:`_BIG_FRAME`): with --jobs 2, two answers just under the 64 MB cap
#: made the grader's peak 2.6x the solutions' (291 MB against 113 MB, benchmarks/bench_grade.py)
BIG_FRAME_BYTES = 8 * 2 ** 20
_BIG_FRAME = threading.Semaphore(1)


def _read_into(fd: int, view: memoryview, deadline: float) -> bool:
    while len(view):
        left = deadline - time.monotonic()
        if left <= 0 or not select.select([fd], [], [], left)[0]:
            return False
        n = os.readv(fd, [view])
        if not n:
            return False
        view = view[n:]
    return True


def _cut(header: dict, whole: bytearray, pos: int, sizes: list) -> tuple[dict, list]:
    view, blobs = memoryview(whole), []
    for s in sizes:
        blobs.append(view[pos: pos + s])
        pos += s
    return header, blobs
