"""Why bubblewrap does not run on this machine, and the fix for each cause (``dtscal grade``'s preflight).

bubblewrap needs an unprivileged user namespace (``bwrap --unshare-user``). The causes seen on
the machines a course grades on, each read from the machine, never guessed from bwrap's words:

* bubblewrap not installed (``bwrap`` not on ``PATH``);
* user namespaces turned off: ``/proc/sys/user/max_user_namespaces`` is 0 (kernel
  ``Documentation/admin-guide/sysctl/user.rst``), or Debian's older
  ``/proc/sys/kernel/unprivileged_userns_clone`` is 0;
* Ubuntu 24.04's AppArmor restriction: ``/proc/sys/kernel/apparmor_restrict_unprivileged_userns``
  is 1 and no AppArmor profile grants bwrap ``userns`` (Ubuntu's "Unprivileged user namespace
  restrictions", 24.04 release notes);
* Docker's default seccomp profile, which refuses ``unshare``/``clone`` with namespace flags to a
  container without ``CAP_SYS_ADMIN`` (docs.docker.com, "Seccomp security profiles for Docker");
* a Kubernetes pod, whose container gets the runtime's default profile and no user namespace
  unless the pod asks for one with ``hostUsers: false`` (kubernetes.io, "Use a User Namespace
  With a Pod").

:func:`diagnose` takes the facts (:func:`facts` reads them) so that each cause is testable.

The other check at the start, :func:`check_numpy`:

Checks at the grader's start: what would make every student "grader error" is refused before grading.

Debian's ``python3-numpy`` reaches BLAS through the alternatives system: its ``_multiarray_umath`` needs
``libblas.so.3``, and ``/usr/lib/<arch>/libblas.so.3`` is a symlink to ``/etc/alternatives/libblas.so.3-<arch>``
(Debian's BLAS packages register ``libblas.so.3`` with ``update-alternatives(1)``; the link on a Debian 12
machine: ``/etc/alternatives/libblas.so.3-x86_64-linux-gnu -> .../openblas-pthread/libblas.so.3``). The
sandbox's manifest recreates every symlink on the way to each library numpy loads, so Debian's numpy runs
inside it; a sandbox that missed one would leave numpy unable to import and every check of every student a
grader error. So before grading, the interpreter and numpy a
submission gets are tried once, inside the sandbox, on a matrix product (BLAS); a failure is a refusal at
start that names the library and the fix, never a class of "grader error" rows.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import threading
from dataclasses import dataclass

from ..errors import DtscalError


#: the option with which the instructor grades where bubblewrap cannot run, knowing the risk
UNCONFINED = "--let-student-code-read-my-files"

@dataclass(frozen=True)
class Cause:
    """One reason bubblewrap fails here, and what the instructor does about it."""

    why: str
    fix: str

    def line(self) -> str:
        return f"{self.why}. Fix: {self.fix}"


def _read(path: str) -> str | None:
    try:
        with open(path) as f:
            return f.read()
    except OSError:
        return None


def _int(text: str | None) -> int | None:
    try:
        return int(str(text).strip())
    except ValueError:
        return None


def facts() -> dict:
    """What :func:`diagnose` needs, read from this machine."""
    status = _read("/proc/self/status") or ""
    seccomp = next((_int(ln.split(":", 1)[1]) for ln in status.splitlines() if ln.startswith("Seccomp:")), None)
    cgroup = _read("/proc/1/cgroup") or ""
    container = None
    if os.environ.get("KUBERNETES_SERVICE_HOST") or "kubepods" in cgroup:
        container = "kubernetes"
    elif os.path.exists("/.dockerenv") or "docker" in cgroup:
        container = "docker"
    return {
        "bwrap": shutil.which("bwrap"),
        "max_user_namespaces": _int(_read("/proc/sys/user/max_user_namespaces")),
        "unprivileged_userns_clone": _int(_read("/proc/sys/kernel/unprivileged_userns_clone")),
        "apparmor_restrict": _int(_read("/proc/sys/kernel/apparmor_restrict_unprivileged_userns")),
        "container": container,
        "seccomp": seccomp,
        "root": os.geteuid() == 0,
    }


def diagnose(f: dict, bwrap_said: str = "") -> list[Cause]:
    """The causes that hold for facts ``f`` (see :func:`facts`), most basic first."""
    out = []
    if not f.get("bwrap"):
        out.append(Cause("bubblewrap (bwrap) is not installed",
                         "run scripts/install-sandbox.sh (Debian/Ubuntu: apt-get install bubblewrap)"))
        return out
    if f.get("max_user_namespaces") == 0:
        out.append(Cause("user namespaces are turned off (/proc/sys/user/max_user_namespaces is 0)",
                         "sysctl -w user.max_user_namespaces=15000 (and the same line in /etc/sysctl.d/ to keep "
                         "it)"))
    if f.get("unprivileged_userns_clone") == 0 and not f.get("root"):
        out.append(Cause("unprivileged user namespaces are turned off (kernel.unprivileged_userns_clone is 0)",
                         "sysctl -w kernel.unprivileged_userns_clone=1, or grade as root"))
    if f.get("apparmor_restrict") == 1:
        out.append(Cause("Ubuntu's AppArmor restricts unprivileged user namespaces "
                         "(kernel.apparmor_restrict_unprivileged_userns is 1)",
                         "give bwrap an AppArmor profile that allows them: a file /etc/apparmor.d/bwrap with "
                         "'abi <abi/4.0>, include <tunables/global> profile bwrap /usr/bin/bwrap flags=(unconfined) "
                         "{ userns, }', then apparmor_parser -r /etc/apparmor.d/bwrap (or, machine-wide, "
                         "sysctl -w kernel.apparmor_restrict_unprivileged_userns=0)"))
    if f.get("container") == "kubernetes":
        out.append(Cause("this is a Kubernetes pod without a user namespace of its own",
                         "set hostUsers: false in the pod spec (Kubernetes 1.30 or newer, user namespaces "
                         "supported by the node), or grade outside the cluster"))
    elif f.get("container") == "docker" and f.get("seccomp"):
        out.append(Cause("this is a Docker container under Docker's default seccomp profile, which refuses new "
                         "namespaces",
                         "start the container with --security-opt seccomp=unconfined (or a profile that allows "
                         "unshare and clone with CLONE_NEWUSER), or grade on the host"))
    if not out:
        out.append(Cause(f"bubblewrap fails here: {bwrap_said.strip()[-300:] or 'no reason given'}",
                         "run `bwrap --unshare-all --ro-bind / / true` to see bubblewrap's own message; "
                         "docs/ta.md lists the usual causes"))
    return out

#: numpy imported and one BLAS call made (a 2x2 product): what every check needs
PROBE = "import numpy; a = numpy.ones((2, 2)); print(float((a @ a)[0, 0]), numpy.__version__)"
PROBE_OUT = "2.0"

_LOCK = threading.Lock()
_DONE: dict = {}


def _reason(stderr: str) -> str:
    """numpy's own "Original error was: ..." line, else the last line of the error."""
    lines = [ln.strip() for ln in stderr.splitlines() if ln.strip()]
    for ln in reversed(lines):
        if ln.startswith("Original error was:"):
            return ln.removeprefix("Original error was:").strip()
    return lines[-1] if lines else "no output"


def _grader_numpy_version() -> str:
    import numpy

    return numpy.__version__


def _grader_numpy_major() -> str:
    return _grader_numpy_version().split(".")[0]


def check_numpy() -> None:
    """Refuse (:class:`DtscalError`) when numpy cannot load and multiply inside the sandbox; once per
    interpreter, numpy and sandbox mode in this process."""
    from . import sandbox

    key = (sandbox.INTERPRETER, sandbox.NUMPY_SITE, sandbox.mode())
    with _LOCK:
        if key in _DONE:
            return
    argv = sandbox.probe_argv(PROBE)
    try:
        run = subprocess.run(argv, capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
        out = run.stdout.split()
        ok, why = run.returncode == 0 and out[:1] == [PROBE_OUT], _reason(run.stderr)
        if ok and len(out) > 1 and out[1].split(".")[0] != _grader_numpy_major():
            # the jobs and answers carry numpy arrays pickled by the grader's numpy: numpy 2 pickles name
            # numpy._core, which numpy 1 cannot load (numpy 2.0 release notes, "numpy.core is now numpy._core")
            ok, why = False, (f"its numpy {out[1]} cannot read the arrays the grader's numpy "
                              f"{_grader_numpy_version()} sends (another major version)")
    except (OSError, subprocess.SubprocessError) as exc:
        ok, why = False, str(exc)
    if not ok:
        m = sandbox.manifest()
        exe, where = m.interpreter, m.trees.get("/sandbox/site/numpy", "numpy")
        debian = "/dist-packages/" in where
        hint = ("" if not debian else "This is Debian's python3-numpy, another numpy than the grader's. "
                if "major version" in why else "This is Debian's python3-numpy, which finds BLAS through "
                "/etc/alternatives (libblas.so.3 -> /etc/alternatives/libblas.so.3-<arch>), outside what the sandbox "
                "shows. ")
        raise DtscalError(
            f"not graded: numpy ({where}, run by {exe}) cannot load or cannot work inside the grading sandbox "
            f"({sandbox.mode()}): {why}. {hint}Every student would get 'grader error', so nothing was graded. "
            "Grade from the kit's own environment, whose numpy (from PyPI) carries its own OpenBLAS: "
            "bash scripts/setup.sh, then .venv/bin/dtscal grade ...")
    with _LOCK:
        _DONE[key] = True
