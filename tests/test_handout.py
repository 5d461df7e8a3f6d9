"""The hand-out: a self-contained student course that starts with one command on a fresh machine."""

from __future__ import annotations

import json
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
    # notebook 06 names install-ros.sh; it sources apt-wait.sh; start.sh sources install-course.sh; nothing else
    assert sorted(p.name for p in (handout / "scripts").iterdir()) == ["apt-wait.sh", "install-course.sh",
                                                                       "install-ros.sh"]
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
    assert len(nbs) == 7 and all(f"`{n}`" in readme for n in nbs)  # the student's whole path
    for words in ("bash start.sh --handin", "git push", "bash start.sh --update", "sudo bash scripts/install-ros.sh",
                  "ROS_MASTER_URI", "ROS_IP"):
        assert words in readme, words
    ta = (handout / "docs" / "ta.md").read_text()
    assert "macOS" in ta and "Windows" in ta and "docker run" in ta and "bash start.sh --handin" in ta
    # the kit-only parts (the hub, the grader, Gradescope, the tests that measured a figure) stay in the kit's copy
    kit_ta = (ROOT / "docs" / "ta.md").read_text()
    assert ta == rel.handout_text(kit_ta) and "dtscal grade" in kit_ta and "jupyterhub_trial_config" in kit_ta
    assert "dtscal grade" not in ta and "nbgitpuller" not in ta and "tests/" not in ta


def test_handout_is_a_git_repository_that_carries_the_workspace(handout, tmp_path):
    """The README's claim: the hand-out is a git repository (one commit of everything, by nobody's name), and the
    student's workspace is part of it; backups, .venv and hand-in zips stay out."""
    import shutil

    repo = tmp_path / "repo"
    # the hand-out as handed out: what another test's start of it made there (.venv, the editable install's
    # egg-info, workspace/, hand-ins) left out
    shutil.copytree(handout, repo, ignore=lambda d, names: [n for n in names if Path(d) == handout and (
        n in (".venv", "workspace", "handin") or n.endswith(".egg-info"))])
    git = ["git", "-c", f"safe.directory={repo}"]
    log = subprocess.run([*git, "log", "--format=%an <%ae>|%s"], cwd=repo, capture_output=True, text=True)
    assert log.returncode == 0, log.stderr  # a repository, with a history
    assert log.stdout.splitlines() == ["dtscal hand-out <handout@dtscal.invalid>|the course as handed out"]
    assert subprocess.run([*git, "status", "--porcelain"], cwd=repo, capture_output=True, text=True,
                          check=True).stdout == ""  # everything handed out is committed
    committed = set(subprocess.run([*git, "ls-files"], cwd=repo, capture_output=True, text=True,
                                   check=True).stdout.split())
    on_disk = {p.relative_to(repo).as_posix() for p in repo.rglob("*") if p.is_file() and ".git" not in
               p.relative_to(repo).parts}
    assert committed == on_disk
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
    (ws / ".update.lock").write_text("")
    subprocess.run([*git, "add", "-A"], cwd=repo, check=True)
    tracked = set(subprocess.run([*git, "ls-files"], cwd=repo, capture_output=True, text=True,
                                 check=True).stdout.split())
    assert {"workspace/01_pinhole_projection.ipynb", "workspace/.course/01_pinhole_projection.ipynb",
            "start.sh", "scripts/install-ros.sh", "scripts/apt-wait.sh", "docs/ta.md", ".gitignore"} <= tracked
    assert not [t for t in tracked if t.startswith(("workspace/backups/", ".venv/", "handin/", "workspace/.update"))]


#: what the hand-out's texts may name that is not a file in it: Duckietown's robot-side folder (the robot keeps
#: its calibrations in /data/config/calibrations/, Duckietown's docs)
NOT_IN_HANDOUT = ("data/config/",)
_PATH = re.compile(r"(?<![\w/.$-])((?:scripts|docs|data|notebooks|dtscal_lib)/[\w./*-]*[\w*/])")
_SOURCES = re.compile(r"""^\s*(?:source|\.)\s+["']?\$\(dirname\s+["']?\$0["']?\)/([^"'\s]+)""", re.M)
_README_SECTION = re.compile(r"README'?s? section \*([^*]+)\*")
_NUMBERED_SECTION = re.compile(r"\bsection (\d+)\b")


def _texts(handout: Path) -> dict[str, str]:
    texts = {"README.md": (handout / "README.md").read_text(), "start.sh": (handout / "start.sh").read_text()}
    for p in sorted((handout / "scripts").glob("*.sh")) + sorted((handout / "docs").glob("*.md")):
        texts[p.relative_to(handout).as_posix()] = p.read_text()
    for p in sorted((handout / "notebooks").glob("*.ipynb")):
        nb = json.loads(p.read_text())
        texts[f"notebooks/{p.name}"] = "\n".join("".join(c["source"]) for c in nb["cells"])
    return texts


def test_every_file_script_and_section_the_handout_names_is_in_it(handout):
    """Issue 23: the hand-out alone. Every script a shipped script sources, every file or folder the README,
    start.sh, the scripts, docs/ and the notebooks name, and every README section a notebook points to, is in
    the hand-out (a path parsed from the text, looked up on disk: independent of how release.py chose them)."""
    texts = _texts(handout)
    assert any(name.startswith("notebooks/06") for name in texts) and "scripts/install-ros.sh" in texts
    missing = []
    for name, text in texts.items():
        for sourced in _SOURCES.findall(text) if name.endswith(".sh") else []:
            if not (handout / name).parent.joinpath(sourced).is_file():
                missing.append(f"{name} sources {sourced}")
        for path in _PATH.findall(text):
            if path.startswith(NOT_IN_HANDOUT):
                continue
            if not list(handout.glob(path.rstrip("/"))):  # the hand-out alone, the TA page too (issue 32)
                missing.append(f"{name} names {path}")
    assert _SOURCES.findall(texts["scripts/install-ros.sh"]) == ["apt-wait.sh"]  # the parse sees the real case
    headings = [line.lstrip("#").strip() for line in texts["README.md"].splitlines() if line.startswith("#")]
    named_sections = [(n, s) for n, t in texts.items() for s in _README_SECTION.findall(t)]
    # on a hub the notebooks come without the hand-out's README: notebook 06 says itself what a robot needs
    assert "README" not in texts["notebooks/06_duckiebot_camera.ipynb"]
    assert "install-ros.sh" in texts["notebooks/06_duckiebot_camera.ipynb"] and "ROS_IP" in \
        texts["notebooks/06_duckiebot_camera.ipynb"]
    for name, section in named_sections:
        if section not in headings:
            missing.append(f"{name} names the README's section *{section}*; the README's sections: {headings}")
    ta_headings = [line for line in texts["docs/ta.md"].splitlines() if line.startswith("#")]
    for number in _NUMBERED_SECTION.findall(texts["docs/ta.md"]):
        if not any(h.startswith(f"## {number}.") for h in ta_headings):
            missing.append(f"docs/ta.md names its section {number}, which it does not have")
    assert missing == []


def test_a_shipped_script_without_what_it_sources_is_found(handout, tmp_path):
    """The check above can fail: the hand-out of before issue 23 (install-ros.sh without apt-wait.sh) is caught."""
    import shutil

    old = tmp_path / "old"
    shutil.copytree(handout / "scripts", old / "scripts")
    (old / "scripts" / "apt-wait.sh").unlink()
    bin_dir = tmp_path / "bin"  # a computer without ROS: no roscore on PATH
    bin_dir.mkdir()
    for tool in ("bash", "dirname"):
        (bin_dir / tool).symlink_to(shutil.which(tool))
    res = subprocess.run([str(bin_dir / "bash"), str(old / "scripts" / "install-ros.sh")], capture_output=True,
                         text=True, env={"PATH": str(bin_dir), "HOME": str(tmp_path)}, timeout=60)
    assert res.returncode != 0 and "apt-wait.sh" in res.stderr  # what the student saw: No such file
    sourced = _SOURCES.findall((old / "scripts" / "install-ros.sh").read_text())
    assert [s for s in sourced if not (old / "scripts" / s).is_file()] == ["apt-wait.sh"]


INSTALL_COURSE = ROOT / "scripts" / "install-course.sh"


def test_start_sh_shows_progress_and_hands_in():
    """The first start prints a line per step and lets the installer show each package (uv, else pip, never
    quiet), through the installer the kit's course.sh shares; --handin runs `dtscal handin`; --setup-only stops
    before JupyterLab."""
    assert "source scripts/install-course.sh" in rel.START_SH
    assert "source scripts/install-course.sh" in (ROOT / "scripts" / "course.sh").read_text()
    text = INSTALL_COURSE.read_text() + rel.START_SH
    assert "[1/3]" in text and "[2/3]" in text and "[3/3]" in text
    installs = [line for line in text.splitlines() if "install" in line and "-e \"$spec\"" in line]
    assert len(installs) == 2 and any("uv" in line for line in installs) and any("pip" in line for line in installs)
    assert not [line for line in text.splitlines() if "install" in line and ("--quiet" in line or " -q" in line)]
    assert 'exec .venv/bin/dtscal handin "$@"' in text
    assert "--setup-only) args+=(\"--no-open\")" in text
    assert subprocess.run(["bash", "-n"], input=rel.START_SH, text=True).returncode == 0


def test_start_sh_help_comes_at_once_and_names_the_handouts_options(handout, tmp_path):
    """`bash start.sh --help` before anything is installed: it prints its usage and installs nothing (no .venv, no
    installer run: PATH holds bash and cat alone, so an install would fail), and names the hand-out's options, not
    the kit's --instructor and --no-open (test_journeys runs each option it names in a set-up hand-out)."""
    import shutil

    course = tmp_path / "course"
    course.mkdir()
    shutil.copy(handout / "start.sh", course / "start.sh")
    shutil.copytree(handout / "scripts", course / "scripts")
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for tool in ("bash", "cat", "dirname"):
        (bin_dir / tool).symlink_to(shutil.which(tool))
    res = subprocess.run([str(bin_dir / "bash"), "start.sh", "--help"], cwd=course, capture_output=True, text=True,
                         env={"PATH": str(bin_dir), "HOME": str(tmp_path)}, timeout=30)
    assert res.returncode == 0 and res.stdout.startswith("usage: bash start.sh"), res.stdout + res.stderr
    assert not (course / ".venv").exists() and res.stderr == ""
    options = set(re.findall(r"--[\w-]+", res.stdout))
    assert {"--no-browser", "--port", "--ip", "--update", "--setup-only", "--handin", "--name", "--help"} <= options
    assert not options & {"--instructor", "--no-open"}, options


def test_start_sh_gives_uv_the_settings_pip_has(tmp_path):
    """uv does not read pip's configuration; start.sh hands pip's settings to uv, so that both install from the same
    places: uv's documented variables (docs.astral.sh/uv, "Environment variables") for pip's options, and pip's rule
    of taking the best version over every index (UV_INDEX_STRATEGY=unsafe-best-match)."""
    code = INSTALL_COURSE.read_text().split("<<'PY'\n", 1)[1].split("\nPY\n", 1)[0]  # the settings reader
    env = {"PATH": os.environ["PATH"], "HOME": str(tmp_path), "PIP_CONFIG_FILE": os.devnull,
           "PIP_INDEX_URL": "https://mirror.example/simple",
           "PIP_EXTRA_INDEX_URL": "https://a.example/simple https://b.example/simple",
           "PIP_FIND_LINKS": "/wheels/one /wheels/two", "PIP_CONSTRAINT": "/etc/course-constraints.txt",
           "PIP_TRUSTED_HOST": "mirror.example", "PIP_DEFAULT_TIMEOUT": "90"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    exports = dict(line.removeprefix("export ").split("=", 1) for line in out.splitlines())
    assert exports == {"UV_INDEX_URL": "https://mirror.example/simple",
                       "UV_EXTRA_INDEX_URL": "'https://a.example/simple https://b.example/simple'",
                       "UV_FIND_LINKS": "/wheels/one,/wheels/two", "UV_CONSTRAINT": "/etc/course-constraints.txt",
                       "UV_INSECURE_HOST": "mirror.example", "UV_HTTP_TIMEOUT": "90",
                       "UV_INDEX_STRATEGY": "unsafe-best-match"}
    env = {k: v for k, v in env.items() if not k.startswith("PIP_") or k == "PIP_CONFIG_FILE"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    assert out.splitlines() == ["export UV_INDEX_STRATEGY=unsafe-best-match"]  # no setting: uv's defaults (PyPI)
