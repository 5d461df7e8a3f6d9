"""The sandbox: each misbehaviour costs the misbehaving function (or check) only.

Every submission here is notebook 02: ``apply_homography`` misbehaves, ``estimate_homography``
is correct. Grading must finish within its limits, write a valid results.json, give
``estimate_homography`` full marks and say plainly what happened to ``apply_homography``.
"""

from __future__ import annotations

import hashlib
import json

import pytest

from dtscal_lib.cli import main as dtscal
from dtscal_lib.grading.grade import grade_file
from dtscal_lib.grading.material import Material
from dtscal_lib.grading.report import gradescope, text, write_json
from nbtools import ROOT, checks_of

HEAD = """
import math
import os
import sys

import numpy as np
"""

ESTIMATE = '''
def _to(H, p):
    q = np.column_stack([p, np.ones(len(p))]) @ np.asarray(H, dtype=float).T
    return q[:, :2] / q[:, 2:3]


def estimate_homography(src, dst):
    src = np.asarray(src, dtype=float)
    dst = np.asarray(dst, dtype=float)

    def hartley(p):
        c = p.mean(axis=0)
        s = math.sqrt(2) / np.mean(np.linalg.norm(p - c, axis=1))
        return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1]])

    Ts, Td = hartley(src), hartley(dst)
    a, b = _to(Ts, src), _to(Td, dst)
    A = []
    for (x, y), (u, v) in zip(a, b):
        A.append([-x, -y, -1, 0, 0, 0, u * x, u * y, u])
        A.append([0, 0, 0, -x, -y, -1, v * x, v * y, v])
    H = np.linalg.inv(Td) @ np.linalg.svd(np.array(A))[2][-1].reshape(3, 3) @ Ts
    return H / H[2, 2]
'''

RIGHT = """
    p = np.column_stack([pts, np.ones(len(pts))]) @ np.asarray(H, dtype=float).T
    return p[:, :2] / p[:, 2:3]
"""

GRADING_CASES = ROOT / "grading" / "cases.py"

# name -> (body of apply_homography, or a whole replacement of its def; text the feedback must show)
MISBEHAVIOURS = {
    "infinite_loop": ("    while True:\n        pass\n", "stopped"),
    "sleep_forever": ("    import time\n    time.sleep(10 ** 6)\n", "time limit"),
    "sys_exit": ("    sys.exit(0)\n", "called sys.exit(0)"),
    "os_exit": ("    os._exit(0)\n", "ended the process"),
    "segfault": ("    import ctypes\n    ctypes.string_at(0)\n", "segmentation fault"),
    "memory_bomb": ("    blocks = []\n    while True:\n        blocks.append(np.empty(10 ** 8))\n", "memory"),
    "list_bomb": ("    blocks = []\n    while True:\n        blocks.append(bytearray(10 ** 8))\n",
                  ("memory", "stopped")),  # which limit comes first depends on the machine's page-fault speed
    "huge_array": ("    return np.ones((10 ** 6, 10 ** 6))\n", "MemoryError"),
    "huge_print": ("    print('x' * 10 ** 8)\n    os.write(1, b'y' * 10 ** 7)\n    return pts * 0\n",
                   "output truncated"),
    "patch_numpy": ("    np.allclose = lambda *a, **k: True\n    np.array_equal = lambda *a, **k: True\n"
                    "    np.testing.assert_allclose = lambda *a, **k: None\n    np.abs = lambda x: x * 0\n"
                    "    return pts * 0\n", "off by"),
    # (names built at run time, so that the academic-honesty rule does not see them first)
    "patch_opencv": ("    cv = __import__('c' + 'v2')\n    setattr(cv, 'perspective' + 'Transform', lambda p, H: p)\n"
                     "    return pts * 1.0\n", "cv2 is not allowed in this exercise"),
    "patch_grader": ("    import importlib\n    c = importlib.import_module('dtscal_lib.grading' + '.checks')\n"
                     "    setattr(c, 'judge_' + 'close', lambda *a: (1.0, ''))\n"
                     "    setattr(c, '_com' + 'pare', lambda *a: '')\n    return pts * 0\n", "academic honesty"),
    "eq_always_true": ("    class Liar:\n        def __eq__(self, other):\n            return True\n"
                       "        __ne__ = lambda self, other: False\n    return Liar()\n", "Liar"),
    "ndarray_subclass": ("    class Same(np.ndarray):\n        def __eq__(self, other):\n"
                         "            return np.ones(np.shape(other), bool)\n"
                         "        def __sub__(self, other):\n            return np.zeros(np.shape(other))\n"
                         "        __rsub__ = __sub__\n"
                         "    return np.zeros((len(pts), 2)).view(Same)\n", "off by"),
    "nan_trick": ("    return np.full((len(pts), 2), np.nan)\n", "NaN"),
    "array_liar": ("    class Fake:\n        def __array__(self, dtype=None, copy=None):\n"
                   "            return np.zeros((3, 2))\n        def __len__(self):\n            return 3\n"
                   "    return Fake()\n", "Fake"),
    # the material is absent from the sandbox's files; sockets and new processes are refused (seccomp)
    "read_material": (f"    text = open({str(GRADING_CASES)!r}).read()\n    print(text)\n    return pts * 0\n",
                      "No such file"),
    "list_material": (f"    print(os.listdir({str(GRADING_CASES.parent)!r}))\n    return pts * 0\n", "No such file"),
    "write_material": (f"    open({str(GRADING_CASES)!r}, 'a').write('# pwned')\n    return pts * 0\n",
                       ("No such file", "Read-only file system")),
    "network": ("    import socket\n    s = socket.socket()\n    s.connect(('127.0.0.1', 9))\n",
                "Operation not permitted"),
    "subprocess": ("    import subprocess\n    subprocess.run(['true'])\n", "Operation not permitted"),
}


def _submission(tmp_path, name, body, *, prefix=""):
    head = "\n\ndef apply_homography(H, pts):\n    pts = np.asarray(pts, dtype=float)\n"
    src = HEAD + prefix + head + body + ESTIMATE
    p = tmp_path / name / "02_homography.py"
    p.parent.mkdir()
    p.write_text(src)
    return p


@pytest.fixture(scope="module")
def material():
    m = Material.load(ROOT)
    m.checks("02_homography")
    return m


@pytest.mark.parametrize("kind", list(MISBEHAVIOURS))
def test_misbehaviour_costs_only_that_function(tmp_path, material, kind):
    body, expect = MISBEHAVIOURS[kind]
    before = hashlib.sha256(GRADING_CASES.read_bytes()).hexdigest()
    sub = _submission(tmp_path, kind, body)
    res = grade_file(sub, material, "02_homography", wall_s=3.0, cpu_s=2, mem_mb=1500)
    apply_, estimate = res.functions
    report = text(res)
    assert estimate.score == estimate.max_score, report
    assert apply_.score < apply_.max_score, report
    assert any(e in report for e in ((expect,) if isinstance(expect, str) else expect)), report
    assert "640173" not in report  # nothing of the grading material reaches the feedback
    if kind in ("sleep_forever", "infinite_loop"):
        # a limit, not the test's patience, ended each check: every check of apply_homography reports it
        # (the submission sleeps 10^6 s or loops forever; a limit that did not fire would hang until
        # pytest-timeout's safety net, 600 s, and fail)
        assert all(expect in t.output for t in apply_.tests), report
    out = write_json(tmp_path / "results.json", gradescope([res]))
    data = json.loads(out.read_text())
    assert len(data["tests"]) == checks_of("02_homography") and data["score"] == res.score
    assert hashlib.sha256(GRADING_CASES.read_bytes()).hexdigest() == before


def test_crash_costs_only_that_check(tmp_path, material):
    """A segfault only for N = 1 costs the 'single point' check; the others pass."""
    body = "    if len(pts) == 1:\n        import ctypes\n        ctypes.string_at(0)\n" + RIGHT
    res = grade_file(_submission(tmp_path, "one", body), material, "02_homography")
    apply_ = res.functions[0]
    failed = [t.name for t in apply_.tests if t.score < t.max_score]
    assert failed == ["a single point (N = 1)"], text(res)
    assert "segmentation fault" in text(res)


@pytest.mark.parametrize("where", ["top_level", "default_argument", "decorator"])
def test_exit_at_import(tmp_path, material, where):
    """``os._exit`` while the submission loads: top-level code never runs; a def whose default
    argument or decorator exits is skipped (that function is lost, the rest is graded)."""
    if where == "top_level":
        prefix, body = "os._exit(3)\nsys.exit(4)\n", RIGHT
    elif where == "default_argument":
        prefix, body = "", None
    else:
        prefix, body = "", None
    if body is None:
        kill = "def apply_homography(H, pts, _=os._exit(3)):" if where == "default_argument" else \
            "@(lambda f: os._exit(3))\ndef apply_homography(H, pts):"
        src = HEAD + "\n\n" + kill + "\n    return pts\n" + ESTIMATE
        sub = tmp_path / "s" / "02_homography.py"
        sub.parent.mkdir()
        sub.write_text(src)
    else:
        sub = _submission(tmp_path, "s", body, prefix=prefix)
    res = grade_file(sub, material, "02_homography")
    apply_, estimate = res.functions
    assert estimate.score == estimate.max_score, text(res)
    if where == "top_level":
        assert apply_.score == apply_.max_score
    else:
        assert apply_.score == 0
        assert any("ended the process" in n for n in res.notes), res.notes


def test_results_json_always_written(tmp_path):
    sub = _submission(tmp_path, "x", "    os._exit(9)\n")
    out = tmp_path / "results.json"
    assert dtscal(["grade", str(sub), "--json", str(out), "--wall", "3", "--cpu", "2", "-q"]) == 0
    data = json.loads(out.read_text())
    assert data["score"] == 10 and len(data["tests"]) == checks_of("02_homography")


def test_grading_without_material_is_refused(tmp_path, capsys):
    sub = _submission(tmp_path, "y", RIGHT)
    assert dtscal(["grade", str(sub), "--material", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "no grading material" in err and "grading/cases.py" in err and "Traceback" not in err


def test_sandbox_notes_say_how_it_isolates(tmp_path):
    from dtscal_lib.grading.sandbox import run_calls

    run = run_calls([("import numpy as np", 1), ("def f(x):\n    return np.asarray(x) * 2", 2)],
                    [{"id": 0, "calls": [("f", (3.0,))], "wall": 5, "cpu": 2}])
    assert run.checks[0].calls[0].value.shape == () and float(run.checks[0].calls[0].value) == 6.0
    assert run.notes["network"]
    assert run.notes["user"]
