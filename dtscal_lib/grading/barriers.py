"""Operating-system barriers around a submission's processes (Linux; each one optional).

Used by :mod:`dtscal_lib.grading.child` before any student code loads. What each barrier
holds, and which ones this machine gives, is reported in the grading notes
(``SandboxRun.notes``) and in ``docs/grading-sandbox.md``:

* **Landlock** (kernel >= 5.13, no privilege needed, also for root): no file can be created,
  written, truncated, removed, renamed or linked outside the check's working folder (ABI 2+
  makes ``rename``/``link`` across folders obey the same rule), nothing can be executed
  (``execve`` of any file is refused, so ``_posixsubprocess.fork_exec`` runs no shell), the
  grading material cannot be read, TCP is refused (ABI 4+), and signals to processes outside
  the submission's own Landlock domain are refused (ABI 6+), so submissions graded side by
  side cannot kill each other.
* **Namespaces** (root, or an unprivileged user namespace): a PID namespace whose init is the
  submission's loader (when it dies the kernel kills every process the submission started),
  a network namespace with loopback only, and (root) a mount namespace where the grading
  material is covered by an empty read-only tmpfs.
* **A fresh uid per submission** (root): the submission runs as a uid no account uses,
  different for submissions graded at the same time, owning only its 0700 working folder.

Nothing here raises when the kernel lacks a feature: the caller records what was applied.
"""

from __future__ import annotations

import ctypes
import os
import platform

CLONE_NEWNS, CLONE_NEWPID, CLONE_NEWNET, CLONE_NEWUSER = 0x00020000, 0x20000000, 0x40000000, 0x10000000
PR_SET_PDEATHSIG, PR_SET_NO_NEW_PRIVS = 1, 38
MS_RDONLY, MS_NOSUID, MS_NODEV, MS_NOEXEC, MS_REC, MS_PRIVATE = 1, 2, 4, 8, 16384, 1 << 18

#: landlock syscall numbers: the same on every architecture (added after the table unification)
SYS_CREATE_RULESET, SYS_ADD_RULE, SYS_RESTRICT_SELF = 444, 445, 446
RULE_PATH_BENEATH = 1
FS = {"execute": 1 << 0, "write_file": 1 << 1, "read_file": 1 << 2, "read_dir": 1 << 3,
      "remove_dir": 1 << 4, "remove_file": 1 << 5, "make_char": 1 << 6, "make_dir": 1 << 7,
      "make_reg": 1 << 8, "make_sock": 1 << 9, "make_fifo": 1 << 10, "make_block": 1 << 11,
      "make_sym": 1 << 12, "refer": 1 << 13, "truncate": 1 << 14}
#: rights that apply to a regular file (a rule on a file may hold only these)
FILE_RIGHTS = FS["execute"] | FS["write_file"] | FS["read_file"] | FS["truncate"]
NET_BIND_TCP, NET_CONNECT_TCP = 1 << 0, 1 << 1
SCOPE_ABSTRACT_UNIX_SOCKET, SCOPE_SIGNAL = 1 << 0, 1 << 1

_libc = None


def libc():
    global _libc
    if _libc is None:
        _libc = ctypes.CDLL(None, use_errno=True)
    return _libc


def _check(ret: int, what: str) -> int:
    if ret < 0:
        err = ctypes.get_errno()
        raise OSError(err, f"{what}: {os.strerror(err)}")
    return ret


def unshare(flags: int) -> None:
    _check(libc().unshare(flags), "unshare")


def set_pdeathsig(sig: int) -> None:
    _check(libc().prctl(PR_SET_PDEATHSIG, sig, 0, 0, 0), "prctl(PDEATHSIG)")


def landlock_abi() -> int:
    """The kernel's Landlock ABI version, 0 when there is none (or not Linux x86/arm)."""
    if platform.system() != "Linux":
        return 0
    try:
        ret = libc().syscall(SYS_CREATE_RULESET, None, ctypes.c_size_t(0), ctypes.c_uint32(1))
    except (AttributeError, OSError):
        return 0
    return max(0, int(ret))


class _RulesetAttr(ctypes.Structure):
    _fields_ = [("handled_access_fs", ctypes.c_uint64), ("handled_access_net", ctypes.c_uint64),
                ("scoped", ctypes.c_uint64)]


class _PathBeneath(ctypes.Structure):
    _pack_ = 1
    _fields_ = [("allowed_access", ctypes.c_uint64), ("parent_fd", ctypes.c_int32)]


def _inside(path: str, folder: str) -> bool:
    return path == folder or path.startswith(folder.rstrip(os.sep) + os.sep)


def _read_rules(hidden: list[str]) -> list[str]:
    """Paths whose subtrees together cover the whole file system except ``hidden``."""
    out: list[str] = []

    def walk(folder: str) -> None:
        try:
            entries = sorted(os.scandir(folder), key=lambda e: e.name)
        except OSError:
            return
        for e in entries:
            p = os.path.join(folder, e.name)
            if any(_inside(p, h) for h in hidden):
                continue
            if any(_inside(h, p) for h in hidden):
                if e.is_dir(follow_symlinks=False):
                    walk(p)
                continue
            try:
                real = os.path.realpath(p)
            except OSError:
                continue
            if any(_inside(real, h) or _inside(h, real) for h in hidden):
                continue  # a link into (or above) the hidden material
            out.append(p)

    if not hidden:
        return ["/"]
    walk("/")
    return out


def landlock(writable: list[str], hidden: list[str], abi: int) -> str:
    """Restrict this process and its future children; returns what was restricted.

    ``writable``: folders where files may be created, written, removed, renamed, linked.
    ``hidden``: folders that may not be read (everything else may be read). Execution of any
    file is refused. Raises OSError when the kernel refuses the ruleset.
    """
    fs = 0
    for k, bit in FS.items():
        if k == "read_dir" or (k == "refer" and abi < 2) or (k == "truncate" and abi < 3):
            continue  # listing folders stays allowed (names only); refer/truncate need newer ABIs
        fs |= bit
    attr = _RulesetAttr(fs, (NET_BIND_TCP | NET_CONNECT_TCP) if abi >= 4 else 0,
                        (SCOPE_SIGNAL | SCOPE_ABSTRACT_UNIX_SOCKET) if abi >= 6 else 0)
    size = 24 if abi >= 6 else 16 if abi >= 4 else 8
    lib = libc()
    rfd = _check(lib.syscall(SYS_CREATE_RULESET, ctypes.byref(attr), ctypes.c_size_t(size), ctypes.c_uint32(0)),
                 "landlock_create_ruleset")
    try:
        write_rights = fs & ~FS["execute"]
        rules = [(p, FS["read_file"]) for p in _read_rules([os.path.realpath(h) for h in hidden])]
        rules += [(os.path.realpath(w), write_rights) for w in writable]
        rules.append(("/dev/null", FS["write_file"] | FS["read_file"]))
        for path, rights in rules:
            try:
                fd = os.open(path, os.O_PATH | os.O_CLOEXEC)
            except OSError:
                continue
            try:
                if not os.path.isdir(path):
                    rights &= FILE_RIGHTS
                pb = _PathBeneath(rights, fd)
                _check(lib.syscall(SYS_ADD_RULE, ctypes.c_int(rfd), ctypes.c_int(RULE_PATH_BENEATH),
                                   ctypes.byref(pb), ctypes.c_uint32(0)), f"landlock_add_rule({path})")
            finally:
                os.close(fd)
        _check(lib.prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0), "prctl(NO_NEW_PRIVS)")
        _check(lib.syscall(SYS_RESTRICT_SELF, ctypes.c_int(rfd), ctypes.c_uint32(0)), "landlock_restrict_self")
    finally:
        os.close(rfd)
    parts = ["writes only in the working folder", "no exec", "material unreadable"]
    if abi >= 4:
        parts.append("no TCP")
    if abi >= 6:
        parts.append("no signals outside the submission")
    return f"Landlock ABI {abi} (" + ", ".join(parts) + ")"


def hide_folders(folders: list[str]) -> None:
    """In a private mount namespace (root): cover ``folders`` with an empty read-only tmpfs."""
    lib = libc()
    _check(lib.mount(None, b"/", None, ctypes.c_ulong(MS_REC | MS_PRIVATE), None), "mount(private)")
    for f in folders:
        if os.path.isdir(f):
            _check(lib.mount(b"none", os.fsencode(f), b"tmpfs",
                             ctypes.c_ulong(MS_RDONLY | MS_NOSUID | MS_NODEV | MS_NOEXEC), b"size=4k"),
                   f"mount(tmpfs on {f})")


def free_uid(slot: int, base: int = 64000) -> int:
    """A uid (and gid) no account on this machine uses, one per concurrent ``slot``."""
    import grp
    import pwd

    uid = base + 2 * slot
    while True:
        try:
            pwd.getpwuid(uid)
        except KeyError:
            try:
                grp.getgrgid(uid)
            except KeyError:
                return uid
        uid += 1


PR_SET_KEEPCAPS, CAP_DAC_READ_SEARCH = 8, 2


class _CapHeader(ctypes.Structure):
    _fields_ = [("version", ctypes.c_uint32), ("pid", ctypes.c_int)]


class _CapData(ctypes.Structure):
    _fields_ = [("effective", ctypes.c_uint32), ("permitted", ctypes.c_uint32), ("inheritable", ctypes.c_uint32)]


def become(uid: int, read_everything: bool) -> None:
    """(root) Become ``uid``/``gid`` with no groups; with ``read_everything``, keep only the
    capability to read any file (CAP_DAC_READ_SEARCH), for a Python installed where other
    users cannot read it (Landlock, where the kernel has it, still hides the material; without
    it that uid is still far less than root: it can write only what it owns, signal only its
    own processes)."""
    lib = libc()
    if read_everything:
        _check(lib.prctl(PR_SET_KEEPCAPS, 1, 0, 0, 0), "prctl(KEEPCAPS)")
    os.setgroups([])
    os.setgid(uid)
    os.setuid(uid)
    if read_everything:
        head = _CapHeader(0x20080522, 0)  # _LINUX_CAPABILITY_VERSION_3
        bit = 1 << CAP_DAC_READ_SEARCH
        data = (_CapData * 2)(_CapData(bit, bit, 0), _CapData(0, 0, 0))
        _check(lib.capset(ctypes.byref(head), data), "capset")
        _check(lib.prctl(PR_SET_KEEPCAPS, 0, 0, 0, 0), "prctl(KEEPCAPS)")
