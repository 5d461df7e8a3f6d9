"""The sandbox holds what its manifest lists, and nothing else (issue 28, item 1).

The whole tree is listed from inside the sandbox (as the grader's user and as an ordinary user)
and compared with :func:`dtscal_lib.grading.sandbox.manifest`: the interpreter, its standard
library, numpy, the harness and exactly the shared libraries those load. So Debian's
``libmrcal.so.2`` (python3-mrcal, scripts/install-mrcal.sh), which a notebook-04 submission once
loaded through ctypes for 30/30, is not there. Also from inside: the working tmpfs has its size,
the root and every bound folder are read-only; and the answer frame's caps hold above them.
"""

from __future__ import annotations

import glob
import io
import json
import os
import struct

import numpy as np
import pytest

from ci import missing
from dtscal_lib.grading import sandbox
from dtscal_lib.grading.harness import MAX_ANSWER_BYTES, MAX_BLOBS
from sandbox_user import readable_python, use
from unprivileged import run_unprivileged, shared_tmp


@pytest.fixture(scope="module", autouse=True)
def bubblewrap():
    ok, why = sandbox.bwrap_available()
    if not ok:
        missing(f"bubblewrap does not run here ({why}); scripts/install-sandbox.sh installs it")


INSIDE = '''
import ctypes
import errno
import os

import numpy as np


def listing():
    out = []
    for d, dirs, files in os.walk("/"):
        if d in ("/proc", "/dev"):
            dirs[:] = []
            continue
        for n in dirs + files:
            p = os.path.join(d, n)
            out.append(("l " if os.path.islink(p) else "d " if os.path.isdir(p) else "f ") + p)
    return np.frombuffer("\\n".join(out).encode(), dtype=np.uint8).copy()


def walls():
    st = os.statvfs("/tmp")
    out = []
    for p in ("/x", "/usr/x", "/sandbox/x", "/sandbox/harness/x", "/sandbox/site/numpy/x"):
        try:
            open(p, "w").close()
            out.append("WROTE " + p)
        except OSError as e:
            out.append(errno.errorcode.get(e.errno, "?"))
    try:
        os.mkdir("/newdir")
        out.append("WROTE /newdir")
    except OSError:
        pass
    for lib in LIBS:  # the route of issue 28: BLAS and LAPACK by path, then mrcal through ctypes
        try:
            ctypes.CDLL(lib)
            out.append("LOADED " + lib)
        except OSError:
            pass
    print(" ".join(out))
    return float(st.f_blocks * st.f_frsize)
'''


def _inside() -> dict:
    """From inside a sandbox: its tree, the tmpfs size, the writes and library loads it tried; and
    the manifest, as this grader (this user) builds it."""
    libs = sorted(glob.glob("/usr/lib/*/libblas.so*") + glob.glob("/usr/lib/*/liblapack.so*")
                  + glob.glob("/usr/lib/*/libmrcal.so*") + ["libmrcal.so.2", "libopencv_core.so"])
    statements = [(f"LIBS = {libs!r}", 1), (INSIDE, 2)]
    run = sandbox.run_calls(statements, [sandbox.CheckJob(id=0, calls=[("listing", ())], wall=30.0, cpu=20),
                                         sandbox.CheckJob(id=1, calls=[("walls", ())], wall=30.0, cpu=20)])
    tree, walls = run.checks[0].calls[0], run.checks[1].calls[0]
    assert tree.ok and walls.ok, (tree.error, walls.error, run.checks)
    m = sandbox.manifest()
    return {"tree": bytes(tree.value).decode().split("\n"), "tmpfs": float(walls.value), "said": walls.stdout,
            "entries": sorted(m.entries()), "trees": {k: v for k, v in m.trees.items()},
            "covered": m.covered, "dynload": m.dynload}


def _compare(got: dict) -> None:
    tree = [ln.split(" ", 1) for ln in got["tree"] if ln]
    files = {p for kind, p in tree if kind != "d"}
    entries = set(got["entries"])
    assert files - entries == set(), f"in the sandbox, not in the manifest: {sorted(files - entries)[:20]}"
    assert entries - files == set(), f"in the manifest, not in the sandbox: {sorted(entries - files)[:20]}"
    allowed = {"/tmp", "/proc", "/dev", *got["covered"], got["dynload"]}
    for p in entries | set(got["trees"]):
        while p != "/":
            p = os.path.dirname(p)
            allowed.add(p)
    inside_trees = tuple(t + "/" for t in got["trees"])
    dirs = {p for kind, p in tree if kind == "d"}
    stray = sorted(d for d in dirs - allowed if not d.startswith(inside_trees))
    assert stray == [], f"folders no manifest entry explains: {stray[:20]}"
    elsewhere = sorted(p for p in files if p.startswith(("/usr/", "/etc/", "/opt/")))
    assert all(p in entries for p in elsewhere)
    assert got["tmpfs"] == sandbox.TMPFS_MB * 2 ** 20, got["tmpfs"]  # the working tmpfs has its size
    words = got["said"].split()
    assert "WROTE" not in words, got["said"]
    loaded = [words[i + 1] for i, w in enumerate(words) if w == "LOADED"]
    # only what the manifest holds loads (Debian's numpy needs libblas and liblapack: they are in it)
    assert all(p in entries for p in loaded) and not any("mrcal" in p or "opencv" in p for p in loaded), loaded


def test_the_sandbox_holds_its_manifest_and_nothing_else():
    if not glob.glob("/usr/lib/*/libmrcal.so*"):
        missing("Debian's python3-mrcal is not installed (scripts/install-mrcal.sh): the ctypes route is untested")
    got = _inside()
    _compare(got)
    assert any(p.endswith("/libc.so.6") for p in got["entries"])  # the ELF closure is there
    assert not any("libmrcal" in p or "libopencv" in p for p in got["entries"])


def test_the_sandbox_holds_its_manifest_as_an_ordinary_user():
    with shared_tmp() as d:
        python = readable_python(d)

        def attempt():
            use(*python)
            return json.dumps(_inside())

        ok, got = run_unprivileged(attempt, timeout=240)
        assert ok, got
        _compare(json.loads(got))


# --------------------------------------------------------------------------- the frame's caps
def _frame(blobs: list[bytes]) -> bytes:
    calls = [{"ok": True, "value": {"kind": "array", "blob": i}} for i in range(len(blobs))]
    head = json.dumps({"calls": calls, "blobs": [len(b) for b in blobs]}).encode()
    return struct.pack(">I", len(head)) + head + b"".join(blobs)


def _npy(arr) -> bytes:
    buf = io.BytesIO()
    np.save(buf, arr)
    return buf.getvalue()


def test_more_arrays_or_bytes_than_the_caps_are_refused():
    small = _npy(np.zeros(1))
    assert len(sandbox.decode_answers(_frame([small] * MAX_BLOBS))) == MAX_BLOBS
    assert sandbox.decode_answers(_frame([small] * (MAX_BLOBS + 1))) is None
    half = _npy(np.zeros(MAX_ANSWER_BYTES // 2, dtype=np.uint8))  # with its .npy header: two are over the cap
    assert sandbox.decode_answers(_frame([half, half])) is None
    assert sandbox.decode_answers(_frame([half])) is not None


DEBIAN_SITE = "/usr/lib/python3/dist-packages"


def test_debian_numpy_through_etc_alternatives(monkeypatch):
    """Debian's numpy (python3-numpy, pulled in by python3-mrcal) loads libblas.so.3 through
    ``/etc/alternatives``: the manifest keeps each link of the way, so the sandbox holds it (and the
    listing still equals the manifest), and numpy's BLAS and LAPACK compute in it."""
    import sys

    python = f"/usr/bin/python{sys.version_info.major}.{sys.version_info.minor}"
    if not (os.path.isdir(f"{DEBIAN_SITE}/numpy") and os.path.exists(python)):
        missing(f"Debian's numpy for {python} is not installed (scripts/install-mrcal.sh installs it)")
    monkeypatch.setattr(sandbox, "INTERPRETER", python)
    monkeypatch.setattr(sandbox, "NUMPY_SITE", DEBIAN_SITE)
    links = sandbox.manifest().links
    assert any(k.startswith("/etc/alternatives/") for k in links), links
    got = _inside()
    _compare(got)
    defs = "def f():\n    a = np.arange(9.0).reshape(3, 3) + np.eye(3)\n    return float(np.linalg.svd(a)[1][0])\n"
    run = sandbox.run_calls([("import numpy as np", 1), (defs, 2)],
                            [sandbox.CheckJob(id=0, calls=[("f", ())], wall=20.0, cpu=10)])
    expected = float(np.linalg.svd(np.arange(9.0).reshape(3, 3) + np.eye(3))[1][0])
    assert abs(float(run.checks[0].calls[0].value) - expected) < 1e-9, run.checks[0]
