"""`dtscal course` (what `scripts/course.sh` ends with) really serves the course in JupyterLab."""

import os
import subprocess
import sys
from pathlib import Path

import pytest
from course_server import _free_port, _stop, check_student_view

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_course_serves_notebooks(tmp_path):
    port = _free_port()
    env = dict(os.environ, JUPYTER_RUNTIME_DIR=str(tmp_path / "rt"), JUPYTER_CONFIG_DIR=str(tmp_path / "cfg"),
               JUPYTER_DATA_DIR=str(tmp_path / "data"))
    proc = subprocess.Popen(
        [sys.executable, "-m", "dtscal_lib.cli", "course", "--no-browser", "--port", str(port), "--ip", "127.0.0.1"],
        cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True,
    )
    try:
        check_student_view(proc, port)
    finally:
        _stop(proc)
