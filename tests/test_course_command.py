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
               JUPYTER_DATA_DIR=str(tmp_path / "data"), DTSCAL_TICK_SECONDS="0.2")
    proc = subprocess.Popen(
        [sys.executable, "-m", "dtscal_lib.cli", "course", "--no-browser", "--port", str(port), "--ip", "127.0.0.1"],
        cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True,
    )
    try:
        lines = check_student_view(proc, port)
        # never quiet while the course opens (issue 32): progress lines come before JupyterLab's address (every
        # 0.2 s here: making the workspace and starting JupyterLab take longer), and they stop once it serves
        said = [i for i, line in enumerate(lines) if "JupyterLab is starting" in line]
        start = next(i for i, line in enumerate(lines) if line.startswith("starting JupyterLab"))
        assert said and said[-1] > start, lines  # also while JupyterLab itself starts, after "starting JupyterLab"
        import psutil

        def helpers():  # the progress helper: the process of `dtscal course` that did not become JupyterLab
            found = []
            for p in psutil.process_iter(["cmdline", "pid"]):
                cmd = " ".join(p.info["cmdline"] or [])
                if "dtscal_lib.cli course" in cmd and f"--port {port}" in cmd and p.info["pid"] != proc.pid:
                    found.append(p)
            return found

        for _ in range(100):  # a safety net only: the helper looks every 0.2 s
            if not helpers():
                break
            psutil.wait_procs(helpers(), timeout=0.1)
        else:
            raise AssertionError("the progress helper still runs after JupyterLab serves")
    finally:
        _stop(proc)
