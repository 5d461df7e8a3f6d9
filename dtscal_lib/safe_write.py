"""The kit's one way to write an output file: atomically, and never over something that is not a file.

Every writer of the kit (the grader's CSV, JSON and class report, the Gradescope bundle, calibration
files and their report page, the hand-in zip, the workspace update, recordings and session archives)
writes through :func:`output` (or :func:`write_bytes` / :func:`write_text`), which decides by what the
target *is* (``os.stat``, symlinks followed):

* **missing or a regular file**: written to a temporary file beside it, flushed, ``fsync``'ed and
  renamed over it (``os.replace``), so a reader never sees half a file and a failure leaves the
  previous file. A symlink to a file keeps being a symlink: the file it names is the one replaced.
* **a character device** (``/dev/null``, ``/dev/stdout`` on a terminal) **or a FIFO** (``/dev/stdout``
  in a pipe, ``mkfifo``): *written through*, as a shell's ``>`` would. The bytes are made in a private
  temporary file first, then copied into it; the device stays a device. A FIFO nobody reads is refused
  (opening it would wait forever).
* **anything else** (a folder, a block device such as a disk, a socket): refused with a
  :class:`~dtscal_lib.errors.DtscalError` that names what it is, before anything is written.

Before this rule, ``dtscal grade --csv /dev/null`` run as root replaced the machine's ``/dev/null``
with a regular 0600 file (the temporary file renamed over the device), and every later ``> /dev/null``
on that machine failed. :func:`check` lets a command refuse a bad target before it does its work.
"""

from __future__ import annotations

import errno
import os
import shutil
import stat
import tempfile
from contextlib import contextmanager
from pathlib import Path

from .errors import DtscalError

#: what a target that is neither a file nor missing is, for the messages
_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISBLK, "a block device (a disk)"), (stat.S_ISSOCK, "a socket"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISFIFO, "a FIFO (named pipe)"))


def _kind(mode: int) -> str:
    for test, name in _KINDS:
        if test(mode):
            return name
    return "not a regular file"


def check(path, *, what: str = "output", through: bool = True) -> str:
    """How ``path`` will be written: ``"replace"`` (missing or a regular file) or ``"through"``
    (a character device or a FIFO, when ``through`` allows it).

    Raises :class:`DtscalError`, naming what the target is and what to give instead, for a folder,
    a block device, a socket, or (``through=False``, for targets that must be files, such as a
    notebook of the workspace) a device or FIFO. Call it before long work, so a bad ``--csv`` is
    refused before the class is graded.
    """
    path = Path(path)
    try:
        st = os.stat(path)
    except OSError as exc:
        if isinstance(exc, FileNotFoundError) and not path.is_symlink():
            return "replace"
        if path.is_symlink():  # a dangling or looping link: the rename would replace the link itself
            raise DtscalError(f"the {what} {path} is a symbolic link that leads nowhere ({exc.strerror}); "
                              "remove it or give another file name") from None
        raise DtscalError(f"cannot look at the {what} {path} ({exc.strerror}); give another file name") from None
    if stat.S_ISREG(st.st_mode):
        return "replace"
    if through and (stat.S_ISCHR(st.st_mode) or stat.S_ISFIFO(st.st_mode)):
        return "through"
    raise DtscalError(f"the {what} {path} is {_kind(st.st_mode)}, not a file: nothing was written there; "
                      "give a file name (an existing file is replaced, a new one is made)")


def real(path) -> Path:
    """The file a (possibly symlinked) target really is, so a rename lands on it and the link stays."""
    path = Path(path)
    return Path(os.path.realpath(path)) if path.is_symlink() else path


def _take_rights(fd: int, path: Path, mode: int | None) -> None:
    """Give the new file ``mode``, else the replaced file's mode (and owner, where allowed), else
    the umask's mode (``mkstemp`` makes 0600; a file replaced in a shared folder must stay readable
    by whoever could read it before)."""
    if not hasattr(os, "fchmod"):  # not POSIX: the platform's defaults apply
        return
    try:
        st = os.stat(path)
    except OSError:
        st = None
    if mode is not None:
        os.fchmod(fd, mode)
    elif st is None:
        os.fchmod(fd, 0o666 & ~umask())
    else:
        os.fchmod(fd, stat.S_IMODE(st.st_mode))
    if st is not None and mode is None and (st.st_uid, st.st_gid) != (os.geteuid(), os.getegid()):
        try:
            os.fchown(fd, st.st_uid, st.st_gid)
        except OSError:  # only root may give files away; the mode is kept all the same
            pass


def umask() -> int:
    """The process's umask, read without changing it where Linux allows (threads may be writing)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)  # elsewhere: the classic read-and-restore
    os.umask(mask)
    return mask


def _open_through(path: Path, what: str) -> int:
    """Open a device or FIFO for writing; a FIFO nobody reads is refused instead of waited on."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        if exc.errno == errno.ENXIO:
            raise DtscalError(f"the {what} {path} is a FIFO (named pipe) that nobody reads; start the reader "
                              "first or give a file name; nothing was written") from None
        raise DtscalError(f"cannot write the {what} to {path} ({exc.strerror}); give a file name") from None
    os.set_blocking(fd, True)
    return fd


def _copy_through(src: Path, path: Path, what: str) -> None:
    fd = _open_through(path, what)
    try:
        with open(src, "rb") as f, os.fdopen(fd, "wb", closefd=False) as out:
            shutil.copyfileobj(f, out, 1 << 20)
    except OSError as exc:
        raise DtscalError(f"writing the {what} to {path} failed ({exc.strerror or exc})") from None
    finally:
        os.close(fd)


@contextmanager
def output(path, *, what: str = "output", mode: int | None = None, keep_rights: bool = True,
           through: bool = True, fsync: bool = True, suffix: str = ".tmp"):
    """Yield a temporary path to write the whole of ``path`` to; on success it becomes ``path``.

    A regular (or missing) target: the temporary file lies beside it and is renamed over it
    (``mode``, or the replaced file's mode and owner with ``keep_rights``, or the umask's).
    A character device or FIFO: the temporary file is private and its bytes are written through
    into the target, which stays what it was. Anything else: :class:`DtscalError` (see
    :func:`check`). On an exception nothing is left behind and the target is untouched.
    """
    path = Path(path)
    how = check(path, what=what, through=through)
    if how == "through":
        fd, tmp = tempfile.mkstemp(prefix="dtscal-out-", suffix=suffix)
        os.close(fd)
        try:
            yield Path(tmp)
            _copy_through(Path(tmp), path, what)
        finally:
            Path(tmp).unlink(missing_ok=True)
        return
    real_path = real(path)
    real_path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{real_path.name}.", suffix=suffix, dir=real_path.parent)
    try:
        if keep_rights or mode is not None:
            _take_rights(fd, real_path, mode)
        os.close(fd)
        fd = -1
        yield Path(tmp)
        if fsync:
            with open(tmp, "rb+") as f:
                os.fsync(f.fileno())
        if check(real_path, what=what, through=through) == "through":  # made a device meanwhile: never replaced
            _copy_through(Path(tmp), real_path, what)
        else:
            os.replace(tmp, real_path)
    finally:
        if fd >= 0:
            os.close(fd)
        Path(tmp).unlink(missing_ok=True)


def write_bytes(path, data: bytes, **kw) -> Path:
    """Write ``data`` as the whole of ``path`` by the rule of :func:`output`; returns ``path``."""
    with output(path, **kw) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text(path, text: str, *, encoding: str = "utf-8", **kw) -> Path:
    """Write ``text`` as the whole of ``path`` by the rule of :func:`output`; returns ``path``."""
    return write_bytes(path, text.encode(encoding), **kw)
