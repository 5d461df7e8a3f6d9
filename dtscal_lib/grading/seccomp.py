"""Seccomp filters for the grading sandbox, written as classic BPF (no libseccomp needed).

Three filters, applied one on top of the other (a seccomp filter can only be added, never
removed, and the strictest answer of all filters wins):

1. :func:`sandbox_filter` goes to bubblewrap (``bwrap --seccomp FD``), so it holds from the
   first instruction of the sandbox's Python: no ``ptrace``, ``mount``/``umount2``/
   ``pivot_root``/``chroot``, ``unshare``/``setns`` and no namespace flags in ``clone``, no
   ``bpf``, ``keyctl``/``add_key``/``request_key``, ``memfd_create``, ``userfaultfd``,
   ``perf_event_open``, ``io_uring_*``, ``process_vm_readv``/``writev``,
   ``open_by_handle_at``, kernel modules, ``kexec``, ``reboot``, ``swapon``, the new mount API,
   no sockets at all (``socket``, ``socketpair``: a numeric exercise never needs one).
   ``execve`` must stay allowed here: bubblewrap's last act is to ``execve`` Python under it.
2. :func:`no_exec_filter`: the harness adds it to itself before any student code is loaded:
   ``execve``/``execveat`` refused (so an ELF written anywhere, in a memfd or the working
   folder, never runs).
3. :func:`worker_filter`: each process that runs student code adds it: no new process or
   thread (``clone``/``fork``/``vfork``/``clone3``), signals only to itself, ``prlimit`` only on
   itself. With it a submission is at most three processes (bubblewrap's init, the trusted
   harness, one worker), so the per-process memory limit bounds the whole submission.

Refused calls fail with ``EPERM`` (``clone3`` with ``ENOSYS``, so that the C library falls back
to ``clone``, whose flags a filter can read); a foreign architecture or x32 system-call number
kills the process. Only x86-64 has the table below (:data:`SYSCALLS`, from the kernel's
``arch/x86/entry/syscalls/syscall_64.tbl``); elsewhere :func:`supported` is False and the
grader says that no seccomp filter holds.

This module is also copied into the sandbox (the harness installs filters 2 and 3 with it): it
imports nothing but the standard library.
"""

from __future__ import annotations

import ctypes
import errno
import os
import platform
import struct

#: x86-64 system-call numbers (arch/x86/entry/syscalls/syscall_64.tbl, Linux 6.x)
SYSCALLS = {
    "ioctl": 16, "socket": 41, "connect": 42, "accept": 43, "sendto": 44, "bind": 49, "listen": 50,
    "socketpair": 53, "clone": 56, "fork": 57, "vfork": 58, "execve": 59, "kill": 62, "fcntl": 72, "ptrace": 101,
    "syslog": 103,
    "rt_sigqueueinfo": 129, "uselib": 134, "personality": 135, "mknod": 133, "modify_ldt": 154,
    "pivot_root": 155, "chroot": 161, "acct": 163, "settimeofday": 164, "mount": 165, "umount2": 166,
    "swapon": 167, "swapoff": 168, "reboot": 169, "iopl": 172, "ioperm": 173, "init_module": 175,
    "delete_module": 176, "quotactl": 179, "tkill": 200, "clock_settime": 227, "tgkill": 234,
    "kexec_load": 246, "add_key": 248, "request_key": 249, "keyctl": 250, "mknodat": 259, "unshare": 272,
    "accept4": 288, "rt_tgsigqueueinfo": 297, "perf_event_open": 298, "fanotify_init": 300, "prlimit64": 302,
    "name_to_handle_at": 303, "open_by_handle_at": 304, "setns": 308, "process_vm_readv": 310,
    "process_vm_writev": 311, "finit_module": 313, "memfd_create": 319, "kexec_file_load": 320, "bpf": 321,
    "execveat": 322, "userfaultfd": 323, "pidfd_send_signal": 424, "io_uring_setup": 425,
    "io_uring_enter": 426, "io_uring_register": 427, "open_tree": 428, "move_mount": 429, "fsopen": 430,
    "fsconfig": 431, "fsmount": 432, "fspick": 433, "pidfd_open": 434, "clone3": 435, "pidfd_getfd": 438,
    "mount_setattr": 442, "memfd_secret": 447,
}
AUDIT_ARCH_X86_64 = 0xC000003E
X32_SYSCALL_BIT = 0x40000000

#: refused everywhere in the sandbox (filter 1)
SANDBOX_DENY = (
    "ptrace", "mount", "umount2", "pivot_root", "chroot", "unshare", "setns", "bpf", "keyctl", "add_key",
    "request_key", "memfd_create", "memfd_secret", "userfaultfd", "perf_event_open", "io_uring_setup",
    "io_uring_enter", "io_uring_register", "process_vm_readv", "process_vm_writev", "open_by_handle_at",
    "name_to_handle_at", "init_module", "finit_module", "delete_module", "kexec_load", "kexec_file_load",
    "reboot", "swapon", "swapoff", "acct", "settimeofday", "clock_settime", "quotactl", "syslog", "uselib",
    "modify_ldt", "iopl", "ioperm", "mknod", "mknodat", "fanotify_init", "open_tree", "move_mount", "fsopen",
    "fsconfig", "fsmount", "fspick", "mount_setattr", "socket", "socketpair", "connect", "bind", "listen",
    "accept", "accept4", "pidfd_getfd",
)
#: ``fcntl`` commands that name a process to signal later (fs/fcntl.c; include/uapi/linux/fcntl.h,
#: asm-generic/fcntl.h): F_SETOWN 8, F_SETSIG 10, F_SETOWN_EX 15. With them and ``O_ASYNC``, one
#: byte written to a pipe made the kernel send SIGKILL to the sandbox's parent (issue 28)
FCNTL_DENY = (8, 10, 15)
#: ``ioctl`` requests of the same kind, and the terminal's (include/uapi/asm-generic/ioctls.h,
#: sockios.h): FIOSETOWN 0x8901, SIOCSPGRP 0x8902 (the owner of SIGIO/SIGURG), TIOCSPGRP 0x5410
#: (a terminal's foreground group: SIGTTIN/SIGTTOU to others), TIOCSCTTY 0x540E, TIOCSTI 0x5412
#: (typing into a terminal of the grader's user, in a sandbox without bubblewrap), TIOCLINUX 0x541C
IOCTL_DENY = (0x8901, 0x8902, 0x5410, 0x540E, 0x5412, 0x541C)
#: refused once the harness runs (filter 2)
EXEC_DENY = ("execve", "execveat")
#: clone flags that make new namespaces (CLONE_NEWNS, NEWCGROUP, NEWUTS, NEWIPC, NEWUSER, NEWPID, NEWNET, NEWTIME)
CLONE_NEW_FLAGS = 0x00020000 | 0x02000000 | 0x04000000 | 0x08000000 | 0x10000000 | 0x20000000 | 0x40000000 | 0x80

RET_ALLOW, RET_KILL_PROCESS, RET_ERRNO = 0x7FFF0000, 0x80000000, 0x00050000
LD_W_ABS, JA, JEQ_K, JGE_K, JSET_K, RET_K = 0x20, 0x05, 0x15, 0x35, 0x45, 0x06
OFF_NR, OFF_ARCH = 0, 4


def _arg(i: int) -> int:
    """Offset of the low 32 bits of argument ``i`` in ``struct seccomp_data`` (little endian)."""
    return 16 + 8 * i


def supported() -> bool:
    """Is there a system-call table here for this machine (Linux on x86-64)?"""
    return platform.system() == "Linux" and platform.machine() in ("x86_64", "AMD64")


class _Prog:
    def __init__(self):
        self.ins: list[tuple[int, int, int, int]] = []

    def add(self, code, k=0, jt=0, jf=0):
        self.ins.append((code, jt, jf, k))

    def bytes(self) -> bytes:
        return b"".join(struct.pack("=HBBI", c, jt, jf, k & 0xFFFFFFFF) for c, jt, jf, k in self.ins)


def _head(p: _Prog) -> None:
    p.add(LD_W_ABS, OFF_ARCH)
    p.add(JEQ_K, AUDIT_ARCH_X86_64, jt=1, jf=0)
    p.add(RET_K, RET_KILL_PROCESS)
    p.add(LD_W_ABS, OFF_NR)
    p.add(JGE_K, X32_SYSCALL_BIT, jt=0, jf=1)
    p.add(RET_K, RET_KILL_PROCESS)


def _deny(p: _Prog, name: str, err: int = errno.EPERM) -> None:
    p.add(JEQ_K, SYSCALLS[name], jt=0, jf=1)
    p.add(RET_K, RET_ERRNO | err)


def _deny_unless_arg(p: _Prog, name: str, arg: int, allowed: tuple[int, ...]) -> None:
    """``name`` refused unless argument ``arg`` (low 32 bits) is one of ``allowed``."""
    n = len(allowed)
    p.add(JEQ_K, SYSCALLS[name], jt=0, jf=n + 3)
    p.add(LD_W_ABS, _arg(arg))
    for i, v in enumerate(allowed):
        p.add(JEQ_K, v & 0xFFFFFFFF, jt=n - i, jf=0)  # to the reload of nr below
    p.add(RET_K, RET_ERRNO | errno.EPERM)
    p.add(LD_W_ABS, OFF_NR)


def _deny_if_flags(p: _Prog, name: str, arg: int, mask: int) -> None:
    """``name`` refused when argument ``arg`` has any bit of ``mask``."""
    p.add(JEQ_K, SYSCALLS[name], jt=0, jf=4)
    p.add(LD_W_ABS, _arg(arg))
    p.add(JSET_K, mask, jt=0, jf=1)
    p.add(RET_K, RET_ERRNO | errno.EPERM)
    p.add(LD_W_ABS, OFF_NR)


def _deny_if_arg(p: _Prog, name: str, arg: int, refused: tuple[int, ...]) -> None:
    """``name`` refused when argument ``arg`` (low 32 bits) is one of ``refused``."""
    n = len(refused)
    p.add(JEQ_K, SYSCALLS[name], jt=0, jf=n + 3)
    p.add(LD_W_ABS, _arg(arg))
    for i, v in enumerate(refused):
        p.add(JEQ_K, v & 0xFFFFFFFF, jt=n - i, jf=0)  # to the refusal below
    p.add(JA, 1)  # none matched: over the refusal
    p.add(RET_K, RET_ERRNO | errno.EPERM)
    p.add(LD_W_ABS, OFF_NR)


def sandbox_filter() -> bytes:
    """Filter 1, for ``bwrap --seccomp``: the sandbox's whole lifetime."""
    p = _Prog()
    _head(p)
    for name in SANDBOX_DENY:
        _deny(p, name)
    _deny_if_arg(p, "fcntl", 1, FCNTL_DENY)
    _deny_if_arg(p, "ioctl", 1, IOCTL_DENY)
    _deny(p, "clone3", errno.ENOSYS)
    _deny_if_flags(p, "clone", 0, CLONE_NEW_FLAGS)
    p.add(RET_K, RET_ALLOW)
    return p.bytes()


def no_exec_filter() -> bytes:
    """Filter 2: no program is ever executed again."""
    p = _Prog()
    _head(p)
    for name in EXEC_DENY:
        _deny(p, name)
    p.add(RET_K, RET_ALLOW)
    return p.bytes()


def worker_filter(pid: int) -> bytes:
    """Filter 3, for the process ``pid`` that runs student code: no process or thread, signals
    and resource limits on itself only."""
    p = _Prog()
    _head(p)
    for name in ("clone", "fork", "vfork"):
        _deny(p, name)
    _deny(p, "clone3", errno.ENOSYS)
    for name in ("pidfd_open", "pidfd_send_signal"):
        _deny(p, name)
    for name in ("kill", "tkill", "tgkill", "rt_sigqueueinfo", "rt_tgsigqueueinfo"):
        _deny_unless_arg(p, name, 0, (pid,))
    _deny_unless_arg(p, "prlimit64", 0, (0, pid))
    p.add(RET_K, RET_ALLOW)
    return p.bytes()


class _SockFprog(ctypes.Structure):
    _fields_ = [("len", ctypes.c_ushort), ("filter", ctypes.c_void_p)]


PR_SET_NO_NEW_PRIVS, PR_SET_SECCOMP, SECCOMP_MODE_FILTER = 38, 22, 2


def install(program: bytes) -> None:
    """Add ``program`` to this process's filters (and every process it starts afterwards)."""
    libc = ctypes.CDLL(None, use_errno=True)
    buf = ctypes.create_string_buffer(program, len(program))
    prog = _SockFprog(len(program) // 8, ctypes.cast(buf, ctypes.c_void_p))
    if libc.prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) != 0:
        err = ctypes.get_errno()
        raise OSError(err, f"prctl(NO_NEW_PRIVS): {os.strerror(err)}")
    if libc.prctl(PR_SET_SECCOMP, SECCOMP_MODE_FILTER, ctypes.byref(prog), 0, 0) != 0:
        err = ctypes.get_errno()
        raise OSError(err, f"prctl(SECCOMP): {os.strerror(err)}")
