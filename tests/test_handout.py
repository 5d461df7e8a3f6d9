"""The hand-out: a self-contained student course that starts with one command on a fresh machine."""

from __future__ import annotations

import os
import subprocess

import pytest

from dtscal_lib import release as rel
from nbtools import ROOT, SOLUTIONS
from course_server import _free_port, _stop, check_student_view


@pytest.fixture(scope="module")
def handout(tmp_path_factory):
    out = tmp_path_factory.mktemp("handout") / "course"
    assert subprocess.run([str(ROOT / ".venv" / "bin" / "dtscal"), "handout", str(out)], capture_output=True,
                          text=True, timeout=300).returncode == 0
    return out


def test_handout_has_no_solution_line_and_no_grading_material(handout):
    sources = sorted(SOLUTIONS.glob("*.ipynb"))
    assert rel.find_solution_leaks(handout, sources) == []
    assert not [p for p in handout.rglob("*") if "grading" in p.relative_to(handout).parts]
    assert not (handout / "solutions").exists() and not (handout / "tests").exists()
    assert not (handout / "benchmarks").exists() and not (handout / "scripts").exists()
    assert (handout / "start.sh").is_file() and (handout / "README.md").read_text() == rel.STUDENT_README
    assert (handout / "data" / "session").is_dir() and (handout / "notebooks" / "01_pinhole_projection.ipynb").exists()


@pytest.mark.slow
@pytest.mark.timeout(1500)
def test_handout_starts_with_one_command_on_a_fresh_machine(handout, tmp_path):
    """`bash start.sh --no-browser` makes its own venv, installs, and serves notebook 01 from the workspace."""
    port = _free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("VIRTUAL_ENV", "PYTHONPATH", "DTSCAL_"))}
    env.update(JUPYTER_RUNTIME_DIR=str(tmp_path / "rt"), JUPYTER_CONFIG_DIR=str(tmp_path / "cfg"),
               JUPYTER_DATA_DIR=str(tmp_path / "data"))
    env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep) if ".venv" not in p)
    proc = subprocess.Popen(["bash", "start.sh", "--no-browser", "--port", str(port), "--ip", "127.0.0.1"],
                            cwd=handout, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            start_new_session=True)
    try:
        check_student_view(proc, port, patience=1200)
        assert (handout / ".venv" / "bin" / "dtscal").exists()
        assert (handout / "workspace" / "01_pinhole_projection.ipynb").exists()
    finally:
        _stop(proc)
