"""What would make a whole class "grader error" is refused at the grader's start, with the reason.

Debian's numpy (``python3-numpy``) loads BLAS through ``/etc/alternatives`` (``libblas.so.3`` is a symlink
there); a sandbox without ``/etc`` made every student of such a grader "grader error". Now such a grader
either grades (the sandbox shows what numpy needs) or refuses before grading, naming the library and the fix.
"""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from ci import missing
from dtscal_lib.cli import main as dtscal
from dtscal_lib.grading import preflight, sandbox
from nbtools import ROOT

DEBIAN_SITE = Path("/usr/lib/python3/dist-packages")
RIGHT = sorted((ROOT / "tests" / "grading_corpus_correct").glob("01_pinhole_projection__*.py"))[0]


@pytest.fixture
def debian_numpy(monkeypatch):
    exe = Path("/usr/bin/python3")
    if not (DEBIAN_SITE / "numpy").is_dir() or not exe.is_file():
        missing("Debian's python3-numpy (apt-get install python3-numpy) is not installed")
    monkeypatch.setattr(sandbox, "INTERPRETER", str(exe))
    monkeypatch.setattr(sandbox, "NUMPY_SITE", str(DEBIAN_SITE))
    sandbox._PROBE.clear()
    preflight._DONE.clear()
    yield
    sandbox._PROBE.clear()
    preflight._DONE.clear()


def test_debian_numpy_grades_or_is_refused_at_start_with_the_reason(debian_numpy, tmp_path, capsys):
    (tmp_path / "class").mkdir()
    (tmp_path / "class" / "ada.py").write_bytes(RIGHT.read_bytes())
    out = tmp_path / "grades.csv"
    code = dtscal(["grade", str(tmp_path / "class"), "--assignment", "01", "--csv", str(out), "-q"])
    err = capsys.readouterr().err
    if code == 0:  # the sandbox shows what Debian's numpy needs: graded like any numpy
        rows = list(csv.DictReader(open(out, newline="")))
        assert [(r["student"], r["total"]) for r in rows] == [("ada", "10")], rows
    else:  # refused before grading: no gradebook of "grader error", the library and the fix named
        assert not out.exists()
        assert "inside the grading sandbox" in err and ("libblas.so.3" in err or "another major version" in err), err
        assert "Debian's python3-numpy" in err and "scripts/setup.sh" in err
    assert "not graded: grader error, rerun" not in err  # never a class of grader errors


def test_the_kits_numpy_passes_the_start_check():
    """The check itself is no obstacle: the kit's own numpy loads and multiplies in the sandbox."""
    preflight._DONE.clear()
    preflight.check_numpy()  # raises if it cannot
    assert preflight._DONE
