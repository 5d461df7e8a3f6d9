"""Every writer of the kit, pointed at something that is not a file, leaves it what it was.

``dtscal grade --csv /dev/null`` run as root once replaced a shared machine's ``/dev/null`` with a
regular 0600 file (the atomic write renamed its temporary file over the device). The rule now
(:mod:`dtscal_lib.safe_write`): a character device or a FIFO is written through (a FIFO nobody reads is
refused with a message), a folder, a disk or a socket is refused, and none of them is ever replaced.

As root each test makes its own character device (``os.mknod`` with ``/dev/null``'s major and minor, in
the test's folder), so a regression replaces the test's node, never the machine's. As an ordinary user
(who cannot make device nodes) the device is the machine's ``/dev/null`` itself, which that user can
write through but cannot replace. The FIFO is the test's own (``mkfifo``) either way.
"""

from __future__ import annotations

import json
import os
import select
import stat
import threading
import zipfile
from pathlib import Path

import nbformat
import numpy as np
import pytest

from dtscal_lib import calib_files, camera, duckietown as dt, report, safe_write
from dtscal_lib.boards import DUCKIETOWN_BOARD
from dtscal_lib.calibration import calibrate
from dtscal_lib.cli import main as dtscal
from dtscal_lib.coverage import Sample
from dtscal_lib.errors import DtscalError
from dtscal_lib.grading import bundle, classreport
from dtscal_lib.grading import report as grade_report
from dtscal_lib.grading.grade import FunctionResult, GradeResult, TestResult
from dtscal_lib.sources import write_compressed_image_bag
from dtscal_lib.teaching import handin, workspace
from dtscal_lib.ui.archive import save_session
from nbtools import ROOT
from unprivileged import run_unprivileged, shared_tmp

KINDS = ("device", "fifo", "link_to_device")


def _device(folder: Path) -> Path:
    """A character device like /dev/null: the test's own under root, the machine's otherwise."""
    if os.geteuid() != 0:
        return Path(os.devnull)
    node = folder / "null-device"
    os.mknod(node, 0o666 | stat.S_IFCHR, os.stat(os.devnull).st_rdev)
    return node


def odd_target(kind: str, folder: Path, name: str) -> tuple[Path, Path]:
    """``(path to give the writer, the node that must stay what it is)`` for one kind of target."""
    folder.mkdir(parents=True, exist_ok=True)
    if kind == "fifo":
        os.mkfifo(folder / name)
        return folder / name, folder / name
    dev = _device(folder)
    if kind == "device":
        if dev == Path(os.devnull):
            return dev, dev
        os.rename(dev, folder / name)
        return folder / name, folder / name
    (folder / name).symlink_to(dev)
    return folder / name, dev


def assert_unchanged(kind: str, given: Path, node: Path) -> None:
    st = os.lstat(node)
    if kind == "fifo":
        assert stat.S_ISFIFO(st.st_mode), f"{node} is no longer a FIFO"
    else:
        assert stat.S_ISCHR(st.st_mode), f"{node} is no longer a character device"
        assert st.st_rdev == os.stat(os.devnull).st_rdev
    if kind == "link_to_device":
        assert given.is_symlink() and Path(os.readlink(given)) == node, "the symlink was replaced"
    leftovers = [p.name for p in given.parent.iterdir() if p.name.startswith(".") and given.name in p.name]
    assert not leftovers, leftovers  # no temporary file left beside it


def written(kind: str, fn, given: Path, node: Path) -> None:
    """Run ``fn`` (the writer); a device is written through, a FIFO nobody reads refused by name."""
    if kind == "fifo":
        with pytest.raises(DtscalError, match="FIFO .*nobody reads"):
            fn()
    else:
        fn()
    assert_unchanged(kind, given, node)


# --------------------------------------------------------------------------- the grader's outputs
def _result(student: str = "ada") -> dict[str, list[GradeResult]]:
    res = GradeResult("ada.ipynb", "01_pinhole_projection", student)
    fr = FunctionResult("project_points")
    fr.tests = [TestResult("project_points: exact", "project_points", 10.0, 10.0, "")]
    res.functions.append(fr)
    return {student: [res]}


@pytest.mark.parametrize("kind", KINDS)
def test_grade_csv(kind, tmp_path):
    given, node = odd_target(kind, tmp_path, "grades.csv")
    written(kind, lambda: grade_report.write_csv(given, _result()), given, node)


@pytest.mark.parametrize("kind", KINDS)
def test_grade_json(kind, tmp_path):
    given, node = odd_target(kind, tmp_path, "results.json")
    written(kind, lambda: grade_report.write_json(given, grade_report.gradescope(_result()["ada"])), given, node)


@pytest.mark.parametrize("kind", KINDS)
def test_class_report(kind, tmp_path):
    given, node = odd_target(kind, tmp_path / "report", "index.html")
    written(kind, lambda: classreport.write_report(tmp_path / "report", _result()), given, node)


@pytest.mark.parametrize("kind", KINDS)
def test_gradescope_bundle(kind, tmp_path):
    given, node = odd_target(kind, tmp_path, "autograder.zip")
    written(kind, lambda: bundle.write_bundle(given), given, node)


def reading(fifo: Path) -> tuple[threading.Thread, list[bytes]]:
    """A reader on ``fifo`` (there before any writer opens it), collecting what one writer sends."""
    fd = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    got: list[bytes] = []

    def read():
        try:
            while True:
                select.select([fd], [], [], 30)
                try:
                    chunk = os.read(fd, 1 << 16)
                except BlockingIOError:
                    continue
                if not chunk:  # the writer came and closed it
                    return
                got.append(chunk)
        finally:
            os.close(fd)

    t = threading.Thread(target=read, daemon=True)
    t.start()
    return t, got


def test_a_fifo_with_a_reader_gets_the_whole_csv(tmp_path):
    """``--csv /dev/stdout`` in a pipe: the bytes arrive through the FIFO, which stays a FIFO."""
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    t, got = reading(fifo)
    grade_report.write_csv(fifo, _result("grace"))
    t.join(30)
    assert b"".join(got).decode().splitlines()[1].startswith("grace,10")
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


def test_dtscal_grade_refuses_a_folder_as_csv_before_grading(tmp_path, capsys):
    """A target that can never be written is refused before the class is graded, by what it is."""
    (tmp_path / "out.csv").mkdir()
    assert dtscal(["grade", str(tmp_path / "nothing-here"), "--csv", str(tmp_path / "out.csv")]) != 0
    err = capsys.readouterr().err
    assert "out.csv is a folder, not a file" in err
    assert "does not exist" not in err  # refused first: the submission not even looked at


def test_a_regular_file_behind_a_symlink_is_replaced_and_the_link_kept(tmp_path):
    (tmp_path / "real.json").write_text("old")
    (tmp_path / "link.json").symlink_to(tmp_path / "real.json")
    grade_report.write_json(tmp_path / "link.json", {"score": 1})
    assert (tmp_path / "link.json").is_symlink()
    assert json.loads((tmp_path / "real.json").read_text()) == {"score": 1}


# --------------------------------------------------------------------------- calibration files and report
@pytest.mark.parametrize("kind", KINDS)
def test_calibration_files(kind, tmp_path):
    given, node = odd_target(kind, tmp_path / "camera_extrinsic", "bot.yaml")
    written(kind, lambda: calib_files.save_extrinsics(dt.default_H(), tmp_path, "bot"), given, node)
    calib = calib_files.load_intrinsics(calib_files.write_defaults(tmp_path / "d")[0])
    given, node = odd_target(kind, tmp_path / "camera_intrinsic", "bot.yaml")
    written(kind, lambda: calib_files.save_intrinsics(calib, tmp_path, "bot"), given, node)
    assert not (tmp_path / "camera_intrinsic" / "bot.yaml.bak").exists()  # nothing to keep of a device


@pytest.fixture(scope="module")
def small_calibration():
    obj = DUCKIETOWN_BOARD.object_points()
    poses = [([0.3, 0.1, 0.0], [-0.09, -0.06, 0.33]), ([0.0, 0.35, 0.05], [-0.12, -0.05, 0.35]),
             ([-0.3, -0.2, -0.04], [-0.08, -0.07, 0.31]), ([0.1, -0.3, 0.1], [-0.1, -0.04, 0.36])]
    views = [camera.project_points(obj, r, t, dt.default_K(), dt.default_dist()) for r, t in poses]
    return calibrate([obj] * len(views), views, dt.IMAGE_SIZE)


@pytest.mark.parametrize("kind", KINDS)
def test_calibration_report_page(kind, tmp_path, small_calibration):
    given, node = odd_target(kind, tmp_path / "rep", "index.html")
    written(kind, lambda: report.write_report(small_calibration, tmp_path / "rep"), given, node)


# --------------------------------------------------------------------------- the student's side
def _handout(tmp_path: Path) -> Path:
    root = tmp_path / "course"
    (root / "workspace").mkdir(parents=True)
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("x = 1")])
    nbformat.write(nb, str(root / "workspace" / "01_pinhole_projection.ipynb"))
    return root


@pytest.mark.parametrize("kind", KINDS)
def test_handin_zip(kind, tmp_path):
    root = _handout(tmp_path)
    given, node = odd_target(kind, root / "handin", "Ada_Lovelace.zip")
    written(kind, lambda: handin.write_handin(root, "Ada Lovelace"), given, node)


@pytest.mark.parametrize("kind", KINDS)
def test_workspace_update(kind, tmp_path):
    """A notebook of the workspace that is a device or FIFO is neither read nor replaced, and said so."""
    root = tmp_path / "kit"
    (root / "notebooks").mkdir(parents=True)
    for name in ("01_pinhole_projection.ipynb", "02_homography.ipynb"):
        (root / "notebooks" / name).write_bytes((ROOT / "notebooks" / name).read_bytes())
    workspace.ensure_workspace(root)
    target = root / "workspace" / "02_homography.ipynb"
    target.unlink()
    given, node = odd_target(kind, target.parent, target.name)
    rep = workspace.update_workspace(root)
    assert any("02_homography.ipynb" in n and "not a file" in n for n in rep.not_carried), rep.not_carried
    assert_unchanged(kind, given, node)


# --------------------------------------------------------------------------- recordings
@pytest.mark.parametrize("kind", KINDS)
def test_recording_bag(kind, tmp_path):
    import cv2

    ok, jpg = cv2.imencode(".jpg", np.zeros((8, 8, 3), np.uint8))
    given, node = odd_target(kind, tmp_path, "rec.bag")
    written(kind, lambda: write_compressed_image_bag(given, "/bot/camera_node/image/compressed",
                                                     [(0, jpg.tobytes())]), given, node)


@pytest.mark.parametrize("kind", KINDS)
def test_live_session_archive(kind, tmp_path):
    corners = DUCKIETOWN_BOARD.object_points()[:, :2] * 1000
    samples = [Sample(corners, np.zeros(4), 0)]
    given, node = odd_target(kind, tmp_path, "session.zip")
    written(kind, lambda: save_session(given, board=DUCKIETOWN_BOARD, image_size=dt.IMAGE_SIZE, robot="bot",
                                       samples=samples), given, node)


def test_a_fifo_written_through_gets_the_whole_zip(tmp_path):
    """Written through means the writer's bytes go into the target: a FIFO with a reader gets the zip."""
    fifo = tmp_path / "session.zip"
    os.mkfifo(fifo)
    t, got = reading(fifo)
    samples = [Sample(DUCKIETOWN_BOARD.object_points()[:, :2] * 1000, np.zeros(4), 0)]
    save_session(fifo, board=DUCKIETOWN_BOARD, image_size=dt.IMAGE_SIZE, robot="bot", samples=samples)
    t.join(30)
    (tmp_path / "copy.zip").write_bytes(b"".join(got))
    assert json.loads(zipfile.ZipFile(tmp_path / "copy.zip").read("session.json"))["robot"] == "bot"


@pytest.mark.parametrize("what", ["folder", "dangling"])
def test_what_cannot_be_written_through_is_refused_by_name(what, tmp_path):
    target = tmp_path / "out.json"
    if what == "folder":
        target.mkdir()
    else:
        target.symlink_to(tmp_path / "nowhere" / "x.json")
    with pytest.raises(DtscalError, match="is a folder, not a file" if what == "folder" else "leads nowhere"):
        safe_write.write_text(target, "{}")
    assert target.is_dir() if what == "folder" else target.is_symlink()


def _csv_through_the_machines_dev_null(folder: str) -> str:
    link = Path(folder) / "to-null.csv"
    link.symlink_to(os.devnull)
    for target in (Path(os.devnull), link):
        grade_report.write_csv(target, _result())
    return "written"


def test_an_ordinary_user_writes_through_the_machines_dev_null():
    """As ``nobody`` (forked from root in CI): ``--csv /dev/null`` is written through, not an error
    about /dev being read-only, and the machine's /dev/null stays a character device."""
    with shared_tmp() as d:
        os.chmod(d, 0o777)
        ok, text = run_unprivileged(_csv_through_the_machines_dev_null, str(d))
        assert ok and text == "written", text
        assert stat.S_ISCHR(os.lstat(os.devnull).st_mode) and (d / "to-null.csv").is_symlink()
