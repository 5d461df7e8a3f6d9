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
