"""The journeys between the kit's steps, each from what the user really holds (issue 23).

* The student: the hand-out, copied away from the kit (a folder under the system's temporary folder,
  outside the checkout) -> ``bash start.sh --setup-only`` (its own ``.venv``, installed by start.sh itself)
  -> code written into a workspace notebook -> ``bash start.sh --handin`` -> the zip. The instructor then
  grades a class folder of such zips in each layout a course produces (zip in the student's folder, zip
  directly in the class folder, both mixed) with the kit's ``dtscal grade``: every student has a row, and the
  CSV and JSON agree, student by student and function by function, with grading the same notebooks unpacked
  (one folder per student, the layout that graded before issue 23).
  The kit's Gradescope autograder grades Ada's zip (as uploaded, and as Gradescope unpacks it) to the same
  scores.
* The update: a corrected course arrives in the hand-out (its ``notebooks/``, as a ``git pull`` of the
  hand-out's repository brings it); ``bash start.sh --update --no-browser --port P`` carries the student's work
  over and then serves the course: JupyterLab answers on P with the updated workspace; no lock file stays.
* The robot: the hand-out's own ``scripts/install-ros.sh`` on a computer without ROS (see its test).

One hand-out and one ``.venv`` serve every journey of this file (module fixtures): start.sh installs once.
"""

from __future__ import annotations

import csv
import json
import os
import re
import shutil
import stat
import subprocess
import sys
import zipfile
from pathlib import Path

import nbformat
import pytest

from course_server import _free_port, _stop, check_student_view
from nbtools import ROOT

pytestmark = pytest.mark.slow

NB01 = "01_pinhole_projection.ipynb"
BEGIN, END = "### BEGIN YOUR CODE", "### END YOUR CODE"
#: eqs. (1)-(2) of the activity: x = K (R X + t), then the perspective division
ADA = ["    Xc = np.asarray(X, float) @ np.asarray(R, float).T + np.asarray(t, float).reshape(1, 3)",
       "    uvw = Xc @ np.asarray(K, float).T",
       "    return uvw[:, :2] / uvw[:, 2:]"]
#: the classic mistake: no perspective division (the pixel is scaled by the depth)
BOB = ["    Xc = np.asarray(X, float) @ np.asarray(R, float).T + np.asarray(t, float).reshape(1, 3)",
       "    uvw = Xc @ np.asarray(K, float).T",
       "    return uvw[:, :2]"]


def _student_env(tmp: Path) -> dict:
    """The student's shell: nothing of the kit's environment (its venv, PYTHONPATH, DTSCAL_*) leaks in."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("VIRTUAL_ENV", "PYTHONPATH", "DTSCAL_"))}
    env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep) if ".venv" not in p)
    env.update(JUPYTER_RUNTIME_DIR=str(tmp / "rt"), JUPYTER_CONFIG_DIR=str(tmp / "cfg"),
               JUPYTER_DATA_DIR=str(tmp / "jdata"))
    return env


@pytest.fixture(scope="module")
def handout(tmp_path_factory):
    """The hand-out as a student holds it: written by the kit, then copied away from it."""
    written = tmp_path_factory.mktemp("instructor") / "handout"
    res = subprocess.run([sys.executable, "-m", "dtscal_lib.cli", "handout", str(written)], cwd=ROOT,
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    student = tmp_path_factory.mktemp("student") / "course"
    shutil.copytree(written, student, symlinks=True)  # handed over: the student's copy, away from the kit
    shutil.rmtree(written)
    assert not student.resolve().is_relative_to(ROOT.resolve())
    return student


@pytest.fixture(scope="module")
def course(handout):
    """The hand-out set up by its own start.sh (no browser, no JupyterLab)."""
    student = handout
    env = _student_env(student.parent)
    res = subprocess.run(["bash", "start.sh", "--setup-only"], cwd=student, env=env, capture_output=True,
                         text=True, timeout=1500)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    assert "[3/3]" in res.stderr and "the course is ready" in res.stderr
    assert (student / "workspace" / NB01).is_file()
    return student


def _write_code(nb_path: Path, func: str, code: list[str]) -> None:
    nb = nbformat.read(str(nb_path), as_version=4)
    cell = next(c for c in nb.cells if f"def {func}(" in c.source)
    lines = cell.source.split("\n")
    b = next(i for i, line in enumerate(lines) if line.strip() == BEGIN)
    e = next(i for i, line in enumerate(lines) if line.strip() == END)
    cell.source = "\n".join(lines[:b + 1] + code + lines[e:])
    nbformat.write(nb, str(nb_path))


def _handin(course: Path, name: str) -> Path:
    res = subprocess.run(["bash", "start.sh", "--handin", "--name", name], cwd=course,
                         env=_student_env(course.parent), capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr
    zpath = course / "handin" / f"{name}.zip"
    assert str(zpath) in res.stdout
    with zipfile.ZipFile(zpath) as z:
        assert sorted(z.namelist()) == sorted(p.name for p in (course / "notebooks").glob("*.ipynb"))
    return zpath


def _grade(folder: Path, out: Path) -> tuple[dict, dict, str, str]:
    """The instructor's `dtscal grade` (this kit) on a class folder: CSV rows by student, JSON by student, the
    class report page, and what the command said on stderr."""
    csv_path, json_path, report = out / "grades.csv", out / "results.json", out / "report"
    res = subprocess.run([sys.executable, "-m", "dtscal_lib.cli", "grade", str(folder), "--jobs", "2", "-q",
                          "--csv", str(csv_path), "--json", str(json_path), "--report", str(report)], cwd=ROOT,
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stdout + res.stderr
    with open(csv_path, newline="") as fh:
        rows = {r["student"]: r for r in csv.DictReader(fh)}
    students = json.loads(json_path.read_text())["students"]
    page = (report / "index.html").read_text().replace(str(folder), "CLASS")
    return rows, students, page, res.stderr


#: the course notebooks with no exercise function, never graded (README's table: 03b and 06, "nothing" to write)
NO_EXERCISE = (("03b_calibration_quality", "notebook 03b"), ("06_duckiebot_camera", "notebook 06"))


def _zip_refused(notes: str) -> list[str]:
    """What a grader said about a hand-in file it did not grade, but for the notebooks without an exercise."""
    return [n for n in re.split(r"\n|; (?=[\w./-]+: )", notes)  # notes: one a line, or "; "-joined in the CSV
            if "not graded" in n and not any(f in n or w in n for f, w in NO_EXERCISE)]


def _per_test(entry: dict) -> dict:
    return {t["name"]: (t["score"], t["max_score"]) for t in entry["tests"]}


@pytest.fixture(scope="module")
def handins(course, tmp_path_factory):
    """Two students' hand-in zips, written by `bash start.sh --handin` after editing the workspace."""
    kept = tmp_path_factory.mktemp("uploads")
    ws = course / "workspace"
    _write_code(ws / NB01, "project_points", ADA)
    ada = Path(shutil.copy(_handin(course, "ada"), kept / "ada.zip"))  # what Ada uploaded
    _write_code(ws / NB01, "project_points", BOB)  # the same hand-out, another student's work
    bob = Path(shutil.copy(_handin(course, "bob"), kept / "bob.zip"))
    return {"ada": ada, "bob": bob}


@pytest.fixture(scope="module")
def unpacked_grades(handins, tmp_path_factory):
    """The class graded from the unpacked notebooks (one folder per student): what every layout must match."""
    tmp = tmp_path_factory.mktemp("unpacked")
    for student, zpath in handins.items():
        with zipfile.ZipFile(zpath) as z:
            z.extractall(tmp / "class" / student)
    return _grade(tmp / "class", tmp)


def test_student_hands_in_zips_and_every_class_layout_grades_as_the_unpacked_notebooks(handins, unpacked_grades,
                                                                                       tmp_path):
    ada, bob = handins["ada"], handins["bob"]

    def layout(name: str, where: dict) -> Path:
        root = tmp_path / name
        for student, (zpath, how) in where.items():
            target = root / student if how != "top" else root
            target.mkdir(parents=True, exist_ok=True)
            if how == "unpacked":
                with zipfile.ZipFile(zpath) as z:
                    z.extractall(target)
            else:
                shutil.copy(zpath, target / f"{student}.zip")
        return root

    want_rows, want_json, want_page, _ = unpacked_grades
    assert set(want_rows) == {"ada", "bob"}
    # independent of the grader's arithmetic: correct code earns all of project_points, the mistake loses points
    ada_pp = {k: v for k, v in _per_test(want_json["ada"]).items() if "project_points" in k}
    bob_pp = {k: v for k, v in _per_test(want_json["bob"]).items() if "project_points" in k}
    assert ada_pp and all(score == mx > 0 for score, mx in ada_pp.values()), ada_pp
    assert sum(s for s, _ in bob_pp.values()) < sum(s for s, _ in ada_pp.values())
    assert float(want_rows["ada"]["project_points"]) > float(want_rows["bob"]["project_points"])

    layouts = {
        "zip in the student's folder": {"ada": (ada, "folder"), "bob": (bob, "folder")},
        "zip directly in the class folder": {"ada": (ada, "top"), "bob": (bob, "top")},
        "zips mixed": {"ada": (ada, "folder"), "bob": (bob, "top")},
        "a zip and an unpacked folder": {"ada": (ada, "top"), "bob": (bob, "unpacked")},
    }
    for name, where in layouts.items():
        out = tmp_path / f"out-{name.replace(' ', '_').replace(chr(39), '')}"
        out.mkdir()
        rows, students, page, stderr = _grade(layout(name.replace(" ", "_").replace("'", ""), where), out)
        assert set(rows) == {"ada", "bob"}, (name, rows.keys(), stderr)  # nobody dropped
        for s in ("ada", "bob"):
            got = {k: v for k, v in rows[s].items() if k != "notes"}
            want = {k: v for k, v in want_rows[s].items() if k != "notes"}
            assert got == want, (name, s, got, want)  # every function, the total and the class's maximum
            assert _per_test(students[s]) == _per_test(want_json[s]), (name, s)
            assert students[s]["score"] == want_json[s]["score"]
            assert _zip_refused(rows[s]["notes"]) == [], (name, s, rows[s]["notes"])
        # the class report: the same distributions, named mistakes and notes; a note names its file where it lies
        # (`ada/ada.zip/06_...` for `ada/06_...` unpacked), so the zip's part of the path is taken out first
        assert re.sub(r"(?:\w+/)?(\w+)\.zip/", r"\1/", page) == want_page, name


@pytest.mark.parametrize("upload", ["the zip as uploaded", "the zip unpacked by Gradescope"])
def test_the_gradescope_bundle_grades_a_handin_as_the_class_grading_does(handins, unpacked_grades, tmp_path,
                                                                        upload):
    """The kit's Gradescope autograder, run as Gradescope runs it (its `run_autograder` over
    /autograder/submission), on Ada's hand-in: the same score, test by test, as `dtscal grade` gave Ada in the
    class, and no file reported as not graded."""
    bundle = tmp_path / "autograder.zip"
    res = subprocess.run([sys.executable, "-m", "dtscal_lib.cli", "grade", "--gradescope-bundle", str(bundle)],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    root = tmp_path / "autograder"
    with zipfile.ZipFile(bundle) as z:
        z.extractall(root / "source")
    sub = root / "submission"
    sub.mkdir()
    if upload == "the zip as uploaded":
        shutil.copy(handins["ada"], sub / "ada.zip")
    else:
        with zipfile.ZipFile(handins["ada"]) as z:
            z.extractall(sub)
    env = dict(os.environ, DTSCAL_AUTOGRADER_ROOT=str(root), DTSCAL_PYTHON=sys.executable,
               PYTHONPATH=str(root / "source"))
    run = subprocess.run(["bash", str(root / "source" / "run_autograder")], env=env, capture_output=True,
                         text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    got = json.loads((root / "results" / "results.json").read_text())
    want = unpacked_grades[1]["ada"]
    assert got["score"] == want["score"] and _per_test(got) == _per_test(want)
    assert _zip_refused(got.get("output", "")) == [], got.get("output")  # notebook 06 alone is "not graded"


def test_update_then_the_course_opens(course, tmp_path):
    """A corrected course arrives; `start.sh --update --no-browser --port P` merges, then JupyterLab answers on P."""
    ws = course / "workspace"
    _write_code(ws / NB01, "project_points", ADA)
    nb = nbformat.read(str(ws / NB01), as_version=4)
    nb.cells.insert(0, nbformat.v4.new_markdown_cell("MY SUMMARY, above the title"))
    nbformat.write(nb, str(ws / NB01))
    new = nbformat.read(str(course / "notebooks" / NB01), as_version=4)  # the corrected course
    fix = nbformat.v4.new_markdown_cell("A correction from your instructor: pixels are (u, v).")
    fix["id"] = "nb01-90"
    new.cells.insert(1, fix)
    nbformat.write(new, str(course / "notebooks" / NB01))
    port = _free_port()
    proc = subprocess.Popen(["bash", "start.sh", "--update", "--no-browser", "--port", str(port), "--ip",
                             "127.0.0.1"], cwd=course, env=_student_env(tmp_path), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, start_new_session=True)
    try:
        check_student_view(proc, port, patience=300)
        merged = nbformat.read(str(ws / NB01), as_version=4)
        sources = [c.source for c in merged.cells]
        assert sources[0] == "MY SUMMARY, above the title"
        assert fix.source in sources
        code = next(c.source for c in merged.cells if "def project_points(" in c.source)
        assert "\n".join(ADA) in code
        assert list((ws / "backups").iterdir())  # the old notebooks kept
        assert not (ws / ".update.lock").exists()
    finally:
        _stop(proc)


PACKAGES = {"ros-core", "python3-rospy", "python3-sensor-msgs", "python3-rosbag", "python3-rostopic"}
#: Debian bookworm's ROS 1 packages for roscore, rospy, sensor_msgs, rosbag and rostopic (packages.debian.org:
#: ros-core ships roscore; python3-rosbag, python3-rostopic the tools; python3-rospy, python3-sensor-msgs the
#: modules the kit's ROS helper imports)


def _fake(path: Path, text: str) -> None:
    path.write_text("#!/bin/bash\n" + text)
    path.chmod(path.stat().st_mode | stat.S_IXUSR | stat.S_IXGRP | stat.S_IXOTH)


def test_robot_setup_from_the_handout_alone_on_a_computer_without_ros(handout, tmp_path):
    """The hand-out's `sudo bash scripts/install-ros.sh` (README, *With a real Duckiebot*), on a computer where
    no ROS tool is on PATH and rospy does not import: it finds the helper it sources in the hand-out itself,
    asks apt for the ROS packages, and says done once they are there.

    ROS is hidden from it: PATH holds only a folder of this test's, with the system tools the script needs
    linked in and no roscore/rosbag/rostopic; apt-get, apt-cache, dpkg-query and sudo are stand-ins that record
    what they are asked (apt-get "install" puts executables named like the tools on that PATH and modules
    named rospy, rosbag and sensor_msgs on PYTHONPATH, as Debian's packages would). What it proves: the shipped
    script and every file it sources run from the hand-out alone, the packages asked for are ROS 1's Debian
    packages, `apt-get update` comes first when apt does not know them, and success is reported only when the
    tools answer. What it does not: that Debian's packages themselves install (scripts/test.sh does that)."""
    kit = tmp_path / "laptop"
    shutil.copytree(handout / "scripts", kit / "scripts")  # the hand-out's scripts, nothing else
    bin_dir, mods, log = tmp_path / "bin", tmp_path / "site", tmp_path / "apt.log"
    bin_dir.mkdir()
    mods.mkdir()
    for tool in ("bash", "dirname", "id", "awk", "stat", "sort", "tr", "cut", "grep", "sleep", "env", "cat",
                 "mkdir", "sed", "head", "ls", "rm", "touch", "chmod", "printf"):
        found = shutil.which(tool)
        if found:
            (bin_dir / tool).symlink_to(found)
    installed = tmp_path / "installed"
    _fake(bin_dir / "sudo", 'exec "$@"\n')
    _fake(bin_dir / "apt-cache", f'echo "apt-cache $*" >> {log}\n'
          f'if [ -e {tmp_path}/updated ]; then echo "  Candidate: 1.17.0-1"; else echo "  Candidate: (none)"; fi\n')
    _fake(bin_dir / "dpkg-query", f'echo "dpkg-query $*" >> {log}\nexit 1\n')
    _fake(bin_dir / "apt-get", f'''echo "apt-get $*" >> {log}
case " $* " in
  *" update "*) touch {tmp_path}/updated ;;
  *" install "*)
    for t in roscore rosbag rostopic; do printf '#!/bin/bash\\n' > {bin_dir}/$t; chmod +x {bin_dir}/$t; done
    mkdir -p {mods}/sensor_msgs; : > {mods}/rospy.py; : > {mods}/rosbag.py; : > {mods}/sensor_msgs/__init__.py
    : > {mods}/sensor_msgs/msg.py; touch {installed} ;;
esac
''')
    env = {"PATH": str(bin_dir), "PYTHONPATH": str(mods), "HOME": str(tmp_path), "LANG": "C.UTF-8",
           "APT_LOCK_FILES": str(tmp_path / "no-lock"), "APT_LOCK_WAIT": "5"}
    res = subprocess.run(["bash", str(kit / "scripts" / "install-ros.sh")], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=120)
    out = res.stdout + res.stderr
    assert "No such file or directory" not in out, out
    assert res.returncode == 0, out
    assert "install-ros: done" in out and installed.exists()
    calls = log.read_text().splitlines()
    updates = [i for i, c in enumerate(calls) if c.startswith("apt-get") and " update" in c]
    installs = [c for c in calls if c.startswith("apt-get") and " install " in c]
    assert updates and len(installs) == 1 and updates[0] < calls.index(installs[0])
    asked = set(installs[0].split(" install ", 1)[1].split()) - {"-y", "--no-install-recommends"}
    assert asked == PACKAGES, asked


# ------------------------------------------------------------------ every command the hand-out shows (issue 32)
#: the programs a shipped text's command starts with; a code span starting otherwise is code or a value, not a command
PROGRAMS = ("bash", "sudo", "git", "export", "dtscal", ".venv/bin/dtscal", "python3", "pip", "docker", "wsl", "ping",
            "rostopic", "apt-get", "scp", "ssh")
#: commands shown for another computer than the student's hand-out, and where each is run instead
ELSEWHERE = {
    "wsl": "Windows' own prompt, before Debian exists (docs/ta.md section 2)",
    "docker": "Docker Desktop on the Mac or Windows (docs/ta.md section 2)",
    "apt-get": "inside the Debian container, as its root (docs/ta.md section 2)",
    "ping": "the laptop, outside the container, to learn the robot's address",
    "rostopic": "a computer with ROS 1 and a robot on its network",
    "scp": "the robot, over the network (notebook 06)",
    "sudo bash scripts/install-ros.sh": "test_robot_setup_from_the_handout_alone_on_a_computer_without_ros, with apt "
                                        "stand-ins (this file)",
    "bash scripts/install-ros.sh": "the same test (inside the container, as root: no sudo)",
}
#: a `dtscal` command shown with a robot or a placeholder is not run: its sub-command and every option it names are
#: checked against the hand-out's own `dtscal SUB --help` (the calibration itself is other tests' subject)
_CODE = re.compile(r"```(\w*)\n(.*?)```|`([^`]+)`", re.S)


def _shown_commands(text: str) -> list[str]:
    """The shell commands a text shows, in the order shown: each line of a ```bash block (comments and `\\`
    continuations handled) and each code span that starts with one of PROGRAMS (a span broken over lines joined)."""
    found = []
    for lang, block, span in _CODE.findall(text):
        if lang == "bash":
            for line in block.replace("\\\n", " ").splitlines():
                line = re.sub(r"\s+#\s.*$", "", line).strip()
                if line and not line.startswith("#"):
                    found.append(line)
        elif span and span.split(None, 1)[0] in PROGRAMS and len(span.split()) > 1:
            found.append(" ".join(span.split()))
    return found


def _in_terminal(cmd: list[str], cwd: Path, env: dict, *, typed: str = "", stop_at: str = "starting JupyterLab",
                 timeout: float = 300) -> tuple[int | None, str]:
    """Run ``cmd`` in a pseudo-terminal, as the student's shell does; type ``typed`` when it asks a question (a
    line ending in ': '). Returns (exit code, or None when it was stopped at ``stop_at``, the terminal's text).
    A command that would open JupyterLab is stopped once it says so (its arguments parsed and its workspace made;
    JupyterLab serving is test_update_then_the_course_opens's and test_handout's)."""
    import pty
    import select
    import signal
    import time

    master, slave = pty.openpty()
    proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdin=slave, stdout=slave, stderr=slave, start_new_session=True)
    os.close(slave)
    out, answered, deadline = "", False, time.monotonic() + timeout
    try:
        while time.monotonic() < deadline:
            ready, _, _ = select.select([master], [], [], 0.5)
            if ready:
                try:
                    chunk = os.read(master, 65536).decode(errors="replace")
                except OSError:  # the terminal closed: the command ended
                    chunk = ""
                out += chunk
                if typed and not answered and out.rstrip(" ").endswith(":") and out.endswith(": "):
                    os.write(master, (typed + "\n").encode())
                    answered = True
                if stop_at in out:
                    os.killpg(proc.pid, signal.SIGTERM)
                    proc.wait(timeout=30)
                    return None, out
                if not chunk and proc.poll() is not None:
                    break
            elif proc.poll() is not None:
                break
        else:
            os.killpg(proc.pid, signal.SIGKILL)
            raise AssertionError(f"{cmd} did not finish in {timeout} s:\n{out[-2000:]}")
        return proc.wait(timeout=30), out
    finally:
        os.close(master)


def test_every_command_the_handout_shows_works_in_the_handout(course, tmp_path):
    """Issue 32: every command the hand-out's texts show a student or a TA (its README, docs/ta.md as the hand-out
    carries it, the notebooks, `bash start.sh --help`, what `--handin` prints) runs in the hand-out as shown, in
    the order shown, in a terminal: `bash start.sh` and its options (up to the point where JupyterLab would start),
    the hand-in (the name asked once on the terminal, then remembered; `--name` replaces the zip), the git hand-in
    to a repository standing in for the course's, `export` lines; commands for another computer are listed in
    ELSEWHERE with where they run. A command no rule covers fails the test (a new command needs a run)."""
    env = _student_env(tmp_path)
    shutil.rmtree(course / "handin", ignore_errors=True)  # a student who never handed in (other journeys did)
    help_code, help_text = _in_terminal(["bash", "start.sh", "--help"], course, env, timeout=30)
    assert help_code == 0 and "usage: bash start.sh" in help_text, help_text
    texts = {"README.md": (course / "README.md").read_text(), "docs/ta.md": (course / "docs" / "ta.md").read_text(),
             "bash start.sh --help": help_text}
    for nb in sorted((course / "notebooks").glob("*.ipynb")):
        texts[nb.name] = "\n".join(c.source for c in nbformat.read(str(nb), as_version=4).cells
                                   if c.cell_type == "markdown")
    origin = tmp_path / "course-repo.git"  # the repository the course gives the student
    subprocess.run(["git", "init", "-q", "--bare", str(origin)], check=True)
    shown = list(dict.fromkeys(c for t in texts.values() for c in _shown_commands(t)))
    options = re.findall(r"^\s+(--[\w-]+)", help_text, re.M)
    assert {"--no-browser", "--port", "--setup-only", "--update", "--handin", "--help"} <= set(options), options
    assert "--instructor" not in help_text and "--no-open" not in help_text  # the kit's, refused in the hand-out
    ran, elsewhere, handin_said = [], [], ""
    while shown:
        cmd = shown.pop(0)
        words = cmd.split()
        where = next((why for key, why in ELSEWHERE.items() if cmd == key or cmd.startswith(key + " ")
                      or words[0] == key), None)
        if where:
            elsewhere.append(cmd)
            continue
        if words[:2] == ["bash", "start.sh"]:
            line = cmd.replace("8890", str(_free_port())).replace("0.0.0.0", "127.0.0.1")
            typed = "Ada Lovelace" if "--handin" in words and "--name" not in words else ""
            code, out = _in_terminal(["bash", "-c", line], course, env, typed=typed)
            assert code in (0, None), (cmd, out[-3000:])  # done, or stopped where JupyterLab starts
            assert "unrecognized arguments" not in out and "Traceback" not in out, (cmd, out[-3000:])
            if "--handin" in words:
                handin_said += out.replace("\r", "")
        elif words[0] in ("dtscal", ".venv/bin/dtscal"):
            res = subprocess.run([".venv/bin/dtscal", words[1], "--help"], cwd=course, env=env, capture_output=True,
                                 text=True, timeout=120)
            assert res.returncode == 0, (cmd, res.stderr)
            named = [w.split("=")[0] for w in words[2:] if w.startswith("--")]
            assert [o for o in named if o not in res.stdout.split()] == [], (cmd, res.stdout)
        elif words[0] in ("git", "export"):
            line = cmd.replace("ADDRESS", str(origin))
            res = subprocess.run(["bash", "-c", line], cwd=course, env=env, capture_output=True, text=True,
                                 timeout=120)
            assert res.returncode == 0, (cmd, res.stdout, res.stderr)
        else:
            raise AssertionError(f"a shipped text shows `{cmd}`, which this test neither runs nor lists in ELSEWHERE")
        ran.append(cmd)
    for option in options:  # every option the help lists is accepted
        if not any(option in c.split() for c in ran) and option != "--help":
            value = {"--port": str(_free_port()), "--ip": "127.0.0.1", "--name": '"Ada Lovelace"',
                     "--out": str(tmp_path / "other.zip")}.get(option, "")
            line = f"bash start.sh {'--handin ' if option in ('--name', '--out') else ''}{option} {value}".strip()
            code, out = _in_terminal(["bash", "-c", line], course, env)
            assert code in (0, None) and "unrecognized" not in out, (line, out[-2000:])
            ran.append(line)
    code, out = _in_terminal(["bash", "start.sh", "--instructor"], course, env, timeout=60)
    assert code == 2 and "bash start.sh --help" in out, out  # refused, saying where the options are

    assert any(c.startswith("bash start.sh --handin --name") for c in ran) and "git remote add origin ADDRESS" in ran
    assert any(c.startswith("git add workspace") for c in ran), ran  # the git hand-in, from the README and --handin
    assert {"wsl", "docker", "apt-get"} <= {c.split()[0] for c in elsewhere}, elsewhere
    # the hand-in: asked once on the terminal, remembered, the --name'd zip the only one left, the name in the message
    assert "Your name" in handin_said and "--name" in handin_said, handin_said
    said_git = re.findall(r"git repositories instead: (.+)", handin_said)
    assert said_git and set(said_git) <= set(ran), said_git  # the --handin message's git command is the one run
    assert sorted(p.name for p in (course / "handin").glob("*.zip")) == ["Ada_Lovelace.zip"]
    # the git hand-in reached the course's repository: the student's workspace, at the branch the roster grades
    pushed = subprocess.run(["git", "--git-dir", str(origin), "ls-tree", "-r", "--name-only", "main"],
                            capture_output=True, text=True, check=True).stdout.split()
    assert f"workspace/{NB01}" in pushed and not [p for p in pushed if p.startswith(("handin/", ".venv/"))]
    # the kit's grader is not in the hand-out: its command says so instead of failing on its arguments
    res = subprocess.run([".venv/bin/dtscal", "grade", "handin/Ada_Lovelace.zip"], cwd=course, env=env,
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 2 and "instructor's kit" in res.stderr and "unrecognized" not in res.stderr, res.stderr


def test_the_handout_reaches_a_robot_over_dtps_from_notebook_06(course, tmp_path):
    """The student's path to a robot today (README, *With a real Duckiebot*): the hand-out as start.sh installed
    it (pip alone, no ROS asked for), notebook 06 with its one line set to ``dtps:ROBOT``, against dtps-http's own
    server publishing the recording on Duckietown's topic (``tests/dtps_robot.py``): the calibrator receives the
    robot's frames. The notebook runs in the hand-out's own ``.venv`` with the student's environment."""
    from dtps_robot import DtpsRobotServer

    nb = nbformat.read(str(course / "notebooks" / "06_duckiebot_camera.ipynb"), as_version=4)
    with DtpsRobotServer(fps=30, step=5) as robot:
        cell = next(c for c in nb.cells if c.get("id") == "nb06-03")
        cell.source = cell.source.replace('source = str(session_dir() / "intrinsics.bag")',
                                          f'source = "{robot.spec}"', 1)
        assert robot.spec in cell.source
        nb.cells.append(nbformat.v4.new_code_cell(
            "import time\n"
            "for _ in range(300):\n"
            "    if calibrator.source.status.frames >= 10:\n"
            "        break\n"
            "    time.sleep(0.1)\n"
            "st = calibrator.source.status\n"
            "print('DTPS', type(calibrator.source).__name__, st.state, st.frames >= 10, st.bad)\n"
            "calibrator.close(); extrinsics.close()"))
        run = tmp_path / "06_dtps.ipynb"
        nbformat.write(nb, str(run))
        res = subprocess.run([str(course / ".venv" / "bin" / "python"), "-m", "nbconvert", "--to", "notebook",
                              "--execute", "--ExecutePreprocessor.timeout=300", "--output", "06_done.ipynb", str(run)],
                             cwd=tmp_path, env=_student_env(tmp_path), capture_output=True, text=True, timeout=900)
        assert res.returncode == 0, res.stderr[-3000:]
    done = nbformat.read(str(tmp_path / "06_done.ipynb"), as_version=4)
    said = "".join(o.get("text", "") for o in done.cells[-1].outputs)
    assert "DTPS DtpsLive running True {}" in said, said
