"""Run a function as an unprivileged user, so that permission tests are real under root.

CI runs as root, and root ignores file permissions: a read-only folder is writable to it.
:func:`run_unprivileged` forks; the child drops to ``nobody`` (``setgroups``, ``setgid``,
``setuid``) when the tests run as root, calls the function in the already loaded
interpreter (which may live in a folder ``nobody`` cannot read, such as ``/root``) and
reports back through a pipe. Without root it runs the function in a child as the current
user. :func:`shared_tmp` makes a folder ``nobody`` can reach (pytest's ``tmp_path`` under
root lies inside a 0700 folder).

The checkout itself may lie in a folder ``nobody`` cannot enter (a clone in ``/root`` or in a
``mktemp -d`` folder): so the child imports every module of ``dtscal_lib`` before it drops its
rights (a lazy import would otherwise fail), and a test hands ``nobody`` copies of its input files
in the shared folder (:func:`readable_copy`), never paths inside the checkout.
"""

from __future__ import annotations

import os
import pwd
import shutil
import signal
import tempfile
from contextlib import contextmanager
from pathlib import Path


def run_unprivileged(fn, *args, timeout: int = 60) -> tuple[bool, str]:
    """``fn(*args)`` in a forked child without root rights: ``(returned normally, str(result or exception))``."""
    read_end, write_end = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: never returns into pytest
        code, text = 1, ""
        try:
            os.close(read_end)
            signal.alarm(timeout)
            if os.geteuid() == 0:
                _import_everything()
                user = pwd.getpwnam("nobody")
                os.setgroups([])
                os.setgid(user.pw_gid)
                os.setuid(user.pw_uid)
                if os.geteuid() == 0:
                    raise RuntimeError("could not drop root rights")
            text, code = str(fn(*args)), 0
        except BaseException as e:  # noqa: BLE001 - everything goes back to the parent
            text = f"{type(e).__name__}: {e}"
        finally:
            try:
                os.write(write_end, text.encode("utf-8", "replace"))
            finally:
                os._exit(code)
    os.close(write_end)
    chunks = []
    while chunk := os.read(read_end, 65536):
        chunks.append(chunk)
    os.close(read_end)
    _, status = os.waitpid(pid, 0)
    return os.waitstatus_to_exitcode(status) == 0, b"".join(chunks).decode("utf-8", "replace")


def _import_everything() -> None:
    """Import every module of dtscal_lib now, while the checkout can still be read."""
    import importlib
    import pkgutil

    import dtscal_lib

    for mod in pkgutil.walk_packages(dtscal_lib.__path__, "dtscal_lib."):
        if mod.name.endswith("__main__"):
            continue
        try:
            importlib.import_module(mod.name)
        except Exception:  # noqa: BLE001 - an optional module (ROS, a browser) is not this test's concern
            pass


def readable_copy(path, folder: Path) -> Path:
    """A copy of ``path`` in ``folder`` (from :func:`shared_tmp`) that ``nobody`` can read (mode 0644)."""
    dst = Path(folder) / Path(path).name
    shutil.copyfile(path, dst)
    os.chmod(dst, 0o644)
    return dst


@contextmanager
def shared_tmp():
    """A fresh folder under the system temp dir that ``nobody`` can enter and read (mode 0755)."""
    d = Path(tempfile.mkdtemp(prefix="dtscal-perm-"))
    os.chmod(d, 0o755)
    try:
        yield d
    finally:
        for sub in [d, *d.rglob("*")]:
            if sub.is_dir() and not sub.is_symlink():
                os.chmod(sub, 0o755)
        shutil.rmtree(d, ignore_errors=True)
