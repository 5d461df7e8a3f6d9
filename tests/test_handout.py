"""The hand-out: a self-contained student course that starts with one command on a fresh machine."""

from __future__ import annotations

import os
from pathlib import Path
import re
import subprocess
import sys

import pytest

from dtscal_lib.teaching import release as rel
from nbtools import ROOT, SOLUTIONS
from course_server import _free_port, _stop, check_student_view


@pytest.fixture(scope="module")
def handout(tmp_path_factory):
    out = tmp_path_factory.mktemp("handout") / "course"
    # this checkout's kit (python -m from its root), whichever checkout the venv was installed from
    assert subprocess.run([sys.executable, "-m", "dtscal_lib.cli", "handout", str(out)], capture_output=True,
                          text=True, timeout=300, cwd=ROOT).returncode == 0
    return out


def test_handout_has_no_solution_line_and_no_grading_material(handout):
    sources = sorted(SOLUTIONS.glob("*.ipynb"))
    assert rel.find_solution_leaks(handout, sources) == []
    assert not [p for p in handout.rglob("*") if "grading" in p.relative_to(handout).parts]
    assert not (handout / "solutions").exists() and not (handout / "tests").exists()
    assert not (handout / "benchmarks").exists()
    assert sorted(p.name for p in (handout / "scripts").iterdir()) == ["install-ros.sh"]  # notebook 06 names it
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


def test_handout_readme_names_only_files_the_handout_has(handout):
    """Every file or folder the student README names in backticks is in the hand-out (or made by start.sh)."""
    readme = (handout / "README.md").read_text()
    named = set(re.findall(r"`([\w./-]+(?:/|\.(?:sh|md|ipynb|py|toml)))`", readme))  # `workspace/`, `docs/ta.md`
    named |= set(re.findall(r"(?<![\w/.])((?:[\w-]+/)*[\w-]+\.(?:sh|md|ipynb|py|toml))\b", readme))  # in commands
    assert {"scripts/install-ros.sh", "docs/ta.md", "start.sh", "workspace/", "notebooks/"} <= named, named
    made_later = ("workspace/", ".venv/", "handin/")  # by start.sh, the course and --handin
    for name in sorted(named):
        if name.startswith(made_later):
            continue
        target = handout / name if "/" in name or not name.endswith(".ipynb") else handout / "notebooks" / name
        assert target.exists(), f"the hand-out README names {name}, which the hand-out does not have"
    nbs = sorted(p.name for p in (handout / "notebooks").glob("*.ipynb"))
    assert len(nbs) == 6 and all(f"`{n}`" in readme for n in nbs)  # the student's whole path
    for words in ("bash start.sh --handin", "git push", "bash start.sh --update", "sudo bash scripts/install-ros.sh",
                  "ROS_MASTER_URI", "ROS_IP"):
        assert words in readme, words
    ta = (handout / "docs" / "ta.md").read_text()
    assert "macOS" in ta and "Windows" in ta and "docker run" in ta and "Ubuntu 24.04" in ta


def test_handout_is_a_git_repository_that_carries_the_workspace(handout, tmp_path):
    """A GitHub Classroom push carries the student's workspace whole; backups, .venv and hand-in zips stay out."""
    import shutil

    repo = tmp_path / "repo"
    # the hand-out as handed out: what another test's start of it made there (.venv, workspace/, hand-ins) left out
    shutil.copytree(handout, repo, ignore=lambda d, names: [n for n in names if Path(d) == handout
                                                            and n in (".venv", "workspace", "handin")])
    ws = repo / "workspace"
    (ws / ".course").mkdir(parents=True)
    (ws / "backups" / "20250101-120000").mkdir(parents=True)
    for name in ("01_pinhole_projection.ipynb", ".course/01_pinhole_projection.ipynb",
                 "backups/20250101-120000/01_pinhole_projection.ipynb"):
        shutil.copyfile(repo / "notebooks" / "01_pinhole_projection.ipynb", ws / name)
    (repo / "handin").mkdir()
    (repo / "handin" / "ada.zip").write_bytes(b"PK")
    (repo / ".venv").mkdir()
    (repo / ".venv" / "x").write_text("x")
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@example.org", "-c", "init.defaultBranch=main"]
    subprocess.run([*git, "init", "-q"], cwd=repo, check=True)
    subprocess.run([*git, "add", "-A"], cwd=repo, check=True)
    tracked = set(subprocess.run(["git", "ls-files"], cwd=repo, capture_output=True, text=True,
                                 check=True).stdout.split())
    assert {"workspace/01_pinhole_projection.ipynb", "workspace/.course/01_pinhole_projection.ipynb",
            "start.sh", "scripts/install-ros.sh", "docs/ta.md", ".gitignore"} <= tracked
    assert not [t for t in tracked if t.startswith(("workspace/backups/", ".venv/", "handin/"))]


def test_start_sh_shows_progress_and_hands_in():
    """The first start prints a line per step and lets pip show each package; --handin runs `dtscal handin`."""
    text = rel.START_SH
    assert "[1/3]" in text and "[2/3]" in text and "[3/3]" in text
    install = next(line for line in text.splitlines() if "pip install" in line and "-e ." in line)
    assert "--quiet" not in install and "--progress-bar on" in install
    assert 'exec .venv/bin/dtscal handin "$@"' in text
    assert subprocess.run(["bash", "-n"], input=text, text=True).returncode == 0
