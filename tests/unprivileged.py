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


#: third-party packages the kit imports lazily (inside functions): their whole package is imported ahead,
#: because the virtualenv, too, may lie in the unreadable checkout (a fresh clone's .venv)
LAZY_PACKAGES = ("rosbags", "lz4", "tqdm", "yaml", "matplotlib.colors", "ipywidgets")


def _import_everything() -> None:
    """Import every module of dtscal_lib and of the lazily imported packages now, while they can be read."""
    import importlib
    import pkgutil

    import dtscal_lib

    names = [m.name for m in pkgutil.walk_packages(dtscal_lib.__path__, "dtscal_lib.")]
    for top in LAZY_PACKAGES:
        try:
            pkg = importlib.import_module(top)
        except Exception:  # noqa: BLE001 - not installed: not this test's concern
            continue
        if hasattr(pkg, "__path__"):
            names += [m.name for m in pkgutil.walk_packages(pkg.__path__, top + ".", onerror=lambda _: None)]
    for name in names:
        if name.endswith("__main__") or ".tests" in name or ".test_" in name:
            continue
        try:
            importlib.import_module(name)
        except Exception:  # noqa: BLE001 - an optional module (ROS, a browser, a backend) is not the test's concern
            pass
    try:  # the ROS message types are built on first use
        from dtscal_lib.sources.bag import _typestore

        _typestore()
    except Exception:  # noqa: BLE001
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
