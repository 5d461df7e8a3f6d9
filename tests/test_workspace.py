"""The student's workspace: created from notebooks/, and updated without losing the student's code."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import nbformat
import pytest

from dtscal_lib.teaching import release as rel
from dtscal_lib.teaching import workspace as ws
from dtscal_lib.errors import DtscalError
from nbtools import ROOT

STUDENT_CODE = [
    "    Xc = np.asarray(X, float) @ np.asarray(R, float).T + np.asarray(t, float).reshape(1, 3)  # mine",
    "    uvw = Xc @ np.asarray(K, float).T",
    "    return uvw[:, :2] / uvw[:, 2:]",
]


def _kit(tmp_path: Path) -> Path:
    """A copy of the kit's solutions/ and generated notebooks/ (what the instructor ships)."""
    root = tmp_path / "kit"
    (root / "solutions").mkdir(parents=True)
    for p in sorted((ROOT / "solutions").glob("0[12]_*.ipynb")):
        shutil.copyfile(p, root / "solutions" / p.name)
    rel.generate_notebooks(root / "solutions", root / "notebooks")
    return root


def _write_student_code(path: Path, func: str, code: list[str]) -> None:
    nb = nbformat.read(str(path), as_version=4)
    for cell in nb.cells:
        if f"def {func}(" in cell.source:
            lines = cell.source.split("\n")
            b = lines.index("    " + rel.BEGIN_YOURS)
            e = lines.index("    " + rel.END_YOURS)
            cell.source = "\n".join(lines[:b + 1] + code + lines[e:])
    nbformat.write(nb, str(path))


def _cell_of(path: Path, func: str) -> str:
    nb = nbformat.read(str(path), as_version=4)
    return next(c.source for c in nb.cells if f"def {func}(" in c.source)


def test_generated_stubs_sit_between_your_code_markers():
    text = (ROOT / "notebooks" / "01_pinhole_projection.ipynb").read_text()
    assert rel.BEGIN_YOURS in text and rel.END_YOURS in text


def test_student_code_survives_a_course_update(tmp_path):
    root = _kit(tmp_path)
    wsdir = ws.ensure_workspace(root)
    assert sorted(p.name for p in wsdir.glob("*.ipynb")) == sorted(p.name for p in (root / "notebooks").glob("*"))
    _write_student_code(wsdir / "01_pinhole_projection.ipynb", "project_points", STUDENT_CODE)
    # the student's workspace is theirs: the generated notebooks stay in sync
    assert rel.check_notebooks(root / "solutions", root / "notebooks") == []

    # the instructor corrects the solution notebook (docstring and text) and regenerates the course
    sol = root / "solutions" / "01_pinhole_projection.ipynb"
    nb = nbformat.read(str(sol), as_version=4)
    for cell in nb.cells:
        if "def project_points(" in cell.source:
            cell.source = cell.source.replace("Project world points into pixels",
                                              "Project world points (metres) into pixels")
    nb.cells.insert(1, nbformat.v4.new_markdown_cell("A correction from your instructor."))
    nbformat.write(nb, str(sol))
    rel.generate_notebooks(root / "solutions", root / "notebooks")

    report = ws.update_workspace(root, stamp="t1")
    assert report.ok, report.text()
    assert report.carried["01_pinhole_projection.ipynb"] == ["project_points"]
    new_cell = _cell_of(wsdir / "01_pinhole_projection.ipynb", "project_points")
    assert "Project world points (metres) into pixels" in new_cell  # the correction arrived
    assert "\n".join(STUDENT_CODE) in new_cell and "NotImplementedError" not in new_cell  # the student's code too
    new_nb = nbformat.read(str(wsdir / "01_pinhole_projection.ipynb"), as_version=4)
    assert new_nb.cells[1].source == "A correction from your instructor."
    backup = wsdir / "backups" / "t1" / "01_pinhole_projection.ipynb"
    assert "\n".join(STUDENT_CODE) in _cell_of(backup, "project_points")
    # the updated function runs
    f = rel.notebook_functions(wsdir / "01_pinhole_projection.ipynb", ["project_points"])["project_points"]
    import numpy as np
    assert np.allclose(f(np.eye(3), np.eye(3), np.zeros(3), np.array([[1.0, 2.0, 4.0]])), [[0.25, 0.5]])


def test_update_reports_code_it_cannot_carry(tmp_path):
    root = _kit(tmp_path)
    wsdir = ws.ensure_workspace(root)
    path = wsdir / "02_homography.ipynb"
    nb = nbformat.read(str(path), as_version=4)
    for cell in nb.cells:  # the student deleted the markers around their code
        if "def apply_homography(" in cell.source:
            cell.source = cell.source.replace("    " + rel.BEGIN_YOURS + "\n", "")
    nbformat.write(nb, str(path))
    report = ws.update_workspace(root, stamp="t2")
    assert not report.ok
    text = report.text()
    assert "KEPT IN A MARKED CELL" in text and "02_homography.ipynb" in text and "backups" in text
    assert (wsdir / "backups" / "t2" / "02_homography.ipynb").exists()


def test_update_without_a_workspace_creates_it(tmp_path):
    root = _kit(tmp_path)
    report = ws.update_workspace(root)
    assert sorted(report.added) == sorted(p.name for p in (root / "notebooks").glob("*.ipynb"))


def test_course_command_roots_students_in_the_workspace_and_opens_notebook_01(tmp_path):
    root = _kit(tmp_path)
    cmd = ws.jupyter_command(root, no_browser=True, port=9999)
    assert f"--ServerApp.root_dir={root / 'workspace'}" in cmd
    assert "--LabApp.default_url=/lab/tree/01_pinhole_projection.ipynb" in cmd
    cmd = ws.jupyter_command(root, instructor=True)
    assert f"--ServerApp.root_dir={root / 'solutions'}" in cmd


# --------------------------------------------------------------------------- the whole notebook survives an update
MY_NOTES = "My notes: K maps camera coordinates to pixels."
MY_SCRATCH = "scratch = project_points(np.eye(3), np.eye(3), np.zeros(3), np.array([[1.0, 2.0, 4.0]]))"
RENAMED = ["    return np.asarray(pts, float) * 0 + 42  # my renamed version"]


def _student_works(wsdir: Path) -> None:
    """A student's afternoon: code, a note, a scratch cell with its output, an output kept, a renamed function."""
    p1 = wsdir / "01_pinhole_projection.ipynb"
    _write_student_code(p1, "project_points", STUDENT_CODE)
    nb = nbformat.read(str(p1), as_version=4)
    ex = next(i for i, c in enumerate(nb.cells) if "def project_points(" in c.source)
    scratch = nbformat.v4.new_code_cell(MY_SCRATCH)
    scratch.outputs = [nbformat.v4.new_output("stream", name="stdout", text="my scratch output\n")]
    nb.cells.insert(ex + 1, scratch)
    nb.cells.insert(1, nbformat.v4.new_markdown_cell(MY_NOTES))
    demo = next(c for c in nb.cells if c.cell_type == "code" and c.get("id") == "nb01-04")
    demo.outputs = [nbformat.v4.new_output("stream", name="stdout", text="course cell output\n")]
    demo.execution_count = 3
    nbformat.write(nb, str(p1))
    p2 = wsdir / "02_homography.ipynb"
    _write_student_code(p2, "apply_homography", RENAMED)
    nb = nbformat.read(str(p2), as_version=4)
    for c in nb.cells:
        c.source = c.source.replace("def apply_homography(", "def apply_h(")
    nbformat.write(nb, str(p2))


def _instructor_corrects(root: Path) -> None:
    sol = root / "solutions" / "01_pinhole_projection.ipynb"
    nb = nbformat.read(str(sol), as_version=4)
    for cell in nb.cells:
        if "def project_points(" in cell.source:
            cell.source = cell.source.replace("Project world points into pixels",
                                              "Project world points (metres) into pixels")
    nb.cells.insert(1, nbformat.v4.new_markdown_cell("A correction from your instructor."))
    nbformat.write(nb, str(sol))
    rel.generate_notebooks(root / "solutions", root / "notebooks")


def _assert_nothing_lost(wsdir: Path) -> None:
    nb = nbformat.read(str(wsdir / "01_pinhole_projection.ipynb"), as_version=4)
    src = [c.source for c in nb.cells]
    assert src.count(MY_NOTES) == 1 and src.count(MY_SCRATCH) == 1  # once, however many updates ran
    notes = src.index(MY_NOTES)
    assert nb.cells[notes - 1].get("id") == "nb01-00"  # where the student put it: after the title cell
    ex = next(i for i, c in enumerate(nb.cells) if "def project_points(" in c.source)
    assert "\n".join(STUDENT_CODE) in nb.cells[ex].source
    assert nb.cells[ex + 1].source == MY_SCRATCH and "my scratch output" in nb.cells[ex + 1].outputs[0]["text"]
    demo = next(c for c in nb.cells if c.get("id") == "nb01-04")
    assert demo.outputs and "course cell output" in demo.outputs[0]["text"] and demo.execution_count == 3
    nb2 = nbformat.read(str(wsdir / "02_homography.ipynb"), as_version=4)
    kept = [c for c in nb2.cells if ws.KEPT_TAG in c.metadata.get("tags", [])]
    assert len(kept) == 1 and kept[0].cell_type == "raw"
    assert "def apply_h(" in kept[0].source and RENAMED[0] in kept[0].source
    assert kept[0].source.startswith("# KEPT BY THE UPDATE: your code for `apply_h` has no place")


def test_update_keeps_own_cells_outputs_and_a_renamed_function(tmp_path):
    root = _kit(tmp_path)
    wsdir = ws.ensure_workspace(root)
    _student_works(wsdir)
    _instructor_corrects(root)
    report = ws.update_workspace(root, stamp="t3")
    assert not report.ok  # the renamed function needs the student's attention: never a silent "ok"
    assert "apply_h" in report.text() and "KEPT IN A MARKED CELL" in report.text()
    assert report.carried["01_pinhole_projection.ipynb"] == ["project_points"]
    assert report.own_cells["01_pinhole_projection.ipynb"] == 2
    _assert_nothing_lost(wsdir)
    nb = nbformat.read(str(wsdir / "01_pinhole_projection.ipynb"), as_version=4)
    assert "A correction from your instructor." in [c.source for c in nb.cells]
    assert "Project world points (metres) into pixels" in _cell_of(wsdir / "01_pinhole_projection.ipynb",
                                                                   "project_points")
    # a second update (nothing new in the course) changes nothing of the student's and duplicates nothing
    ws.update_workspace(root, stamp="t4")
    _assert_nothing_lost(wsdir)


def test_update_keeps_a_course_cell_the_student_edited(tmp_path):
    root = _kit(tmp_path)
    wsdir = ws.ensure_workspace(root)
    p1 = wsdir / "01_pinhole_projection.ipynb"
    nb = nbformat.read(str(p1), as_version=4)
    demo = next(c for c in nb.cells if c.get("id") == "nb01-04")
    demo.source += "\nprint('my tweak')"
    nbformat.write(nb, str(p1))
    _instructor_corrects(root)  # the course does not change nb01-04: the student's edit stays in place
    ws.update_workspace(root, stamp="t5")
    nb = nbformat.read(str(p1), as_version=4)
    assert next(c for c in nb.cells if c.get("id") == "nb01-04").source.endswith("print('my tweak')")
    # the course changes that cell too: the new version, and the student's just below it, marked
    sol = root / "solutions" / "01_pinhole_projection.ipynb"
    snb = nbformat.read(str(sol), as_version=4)
    sdemo = next(c for c in snb.cells if c.get("id") == "nb01-04")
    sdemo.source = "# corrected by the instructor\n" + sdemo.source
    nbformat.write(snb, str(sol))
    rel.generate_notebooks(root / "solutions", root / "notebooks")
    report = ws.update_workspace(root, stamp="t6")
    nb = nbformat.read(str(p1), as_version=4)
    i = next(i for i, c in enumerate(nb.cells) if c.get("id") == "nb01-04")
    assert nb.cells[i].source.startswith("# corrected by the instructor")
    assert nb.cells[i + 1].cell_type == "raw" and nb.cells[i + 1].source.endswith("print('my tweak')")
    assert not report.ok and "course changed it too" in report.text()


def test_two_updates_in_one_second_keep_two_backups(tmp_path):
    root = _kit(tmp_path)
    wsdir = ws.ensure_workspace(root)
    _student_works(wsdir)
    first = (wsdir / "01_pinhole_projection.ipynb").read_bytes()
    ws.update_workspace(root, stamp="same")
    _instructor_corrects(root)
    second = (wsdir / "01_pinhole_projection.ipynb").read_bytes()
    ws.update_workspace(root, stamp="same")
    assert (wsdir / "backups" / "same" / "01_pinhole_projection.ipynb").read_bytes() == first
    assert (wsdir / "backups" / "same-2" / "01_pinhole_projection.ipynb").read_bytes() == second
    _assert_nothing_lost(wsdir)


def _update_in_child(root: str, conn) -> None:
    try:
        conn.send(("ok", ws.update_workspace(root, stamp="double-click").text()))
    except BaseException as exc:  # noqa: BLE001 - reported to the parent
        conn.send((type(exc).__name__, str(exc)))


def test_two_updates_at_once_both_finish_and_lose_nothing(tmp_path):
    import multiprocessing

    root = _kit(tmp_path)
    wsdir = ws.ensure_workspace(root)
    _student_works(wsdir)
    _instructor_corrects(root)
    ctx = multiprocessing.get_context("fork")
    pipes, procs = [], []
    for _ in range(2):  # a double click: two updates started together; the lock makes the second wait
        a, b = ctx.Pipe()
        p = ctx.Process(target=_update_in_child, args=(str(root), b))
        pipes.append(a)
        procs.append(p)
    for p in procs:
        p.start()
    answers = [a.recv() if a.poll(120) else ("no answer", "") for a in pipes]
    for p in procs:
        p.join(60)
    assert [kind for kind, _ in answers] == ["ok", "ok"], answers
    assert sorted(d.name for d in (wsdir / "backups").iterdir()) == ["double-click", "double-click-2"]
    _assert_nothing_lost(wsdir)
    assert not list(wsdir.glob(".*.tmp")) and not list(wsdir.glob(".*.old-*"))


def test_an_update_while_another_holds_the_lock_refuses_and_changes_nothing(tmp_path):
    import fcntl

    root = _kit(tmp_path)
    wsdir = ws.ensure_workspace(root)
    _student_works(wsdir)
    _instructor_corrects(root)
    before = {p.name: p.read_bytes() for p in wsdir.glob("*.ipynb")}
    fd = os.open(wsdir / ws.LOCK, os.O_RDWR | os.O_CREAT)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        with pytest.raises(DtscalError, match="another update of this workspace is still running"):
            ws.update_workspace(root, lock_wait_s=0.5)
    finally:
        os.close(fd)
    assert {p.name: p.read_bytes() for p in wsdir.glob("*.ipynb")} == before
    assert not (wsdir / "backups").exists()
    ws.update_workspace(root)  # the lock is free again
    _assert_nothing_lost(wsdir)


def _cli_update(root: Path) -> tuple[int, str]:
    """``dtscal course --update`` on ``root`` as the command line runs it (exit code, stderr)."""
    import contextlib
    import io
    from unittest import mock

    from dtscal_lib import cli

    err = io.StringIO()
    with mock.patch("dtscal_lib.paths.repo_root", return_value=root), contextlib.redirect_stderr(err), \
            contextlib.redirect_stdout(io.StringIO()):
        code = cli.main(["course", "--update", "--no-open"])
    return code, err.getvalue()


def _snapshot(wsdir: Path) -> dict:
    return {str(p.relative_to(wsdir)): p.read_bytes() for p in sorted(wsdir.rglob("*")) if p.is_file()
            and p.name != ws.LOCK}


def test_update_with_backups_a_file_says_what_to_do(tmp_path):
    root = _kit(tmp_path)
    wsdir = ws.ensure_workspace(root)
    _student_works(wsdir)
    _instructor_corrects(root)
    (wsdir / "backups").write_text("not a folder")
    before = _snapshot(wsdir)
    code, err = _cli_update(root)
    assert code == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert "backups is a file, not a folder; rename or delete it" in err and "nothing was changed" in err
    assert _snapshot(wsdir) == before


def _update_as_unprivileged(root: str) -> str:
    try:
        ws.update_workspace(root)
    except DtscalError as exc:
        return f"refused: {exc}"
    return "updated"


def test_update_of_a_read_only_notebook_refuses_and_changes_nothing():
    from unprivileged import run_unprivileged, shared_tmp

    with shared_tmp() as tmp:
        root = _kit(tmp)
        wsdir = ws.ensure_workspace(root)
        _student_works(wsdir)
        _instructor_corrects(root)
        if os.geteuid() == 0:  # the child runs as nobody: the workspace is theirs, as a student's is
            import pwd

            user = pwd.getpwnam("nobody")
            for p in [wsdir, *wsdir.rglob("*")]:
                os.chown(p, user.pw_uid, user.pw_gid)
        (wsdir / "02_homography.ipynb").chmod(0o444)
        before = _snapshot(wsdir)
        ok, text = run_unprivileged(_update_as_unprivileged, str(root))
        assert ok, text
        assert text.startswith("refused: ") and "02_homography.ipynb is read-only" in text
        assert "make it writable" in text and "nothing was changed" in text and "\n" not in text
        assert _snapshot(wsdir) == before


def _update_with_a_small_file_limit(root: str, limit: int) -> str:
    import resource
    import signal

    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG, as on a full disk
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return _update_as_unprivileged(root)


def test_update_that_cannot_write_a_whole_notebook_changes_nothing(tmp_path):
    """Writes cut short (a file-size limit: a write past half the largest notebook fails, as on a full disk)."""
    import multiprocessing

    root = _kit(tmp_path)
    wsdir = ws.ensure_workspace(root)
    _student_works(wsdir)
    _instructor_corrects(root)
    before = _snapshot(wsdir)
    limit = max(p.stat().st_size for p in wsdir.glob("*.ipynb")) // 2
    ctx = multiprocessing.get_context("fork")
    a, b = ctx.Pipe()

    def child(conn):
        try:
            conn.send(_update_with_a_small_file_limit(str(root), limit))
        except BaseException as exc:  # noqa: BLE001 - a traceback is a failure the parent reports
            conn.send(f"{type(exc).__name__}: {exc}")

    p = ctx.Process(target=child, args=(b,))
    p.start()
    assert a.poll(60), "the update in the child neither finished nor failed"
    text = a.recv()
    p.join(60)
    assert text.startswith("refused: ") and "the disk is full" in text and "nothing was changed" in text, text
    assert _snapshot(wsdir) == before
    assert not list(wsdir.rglob("*.tmp"))
    assert not (wsdir / "backups").exists() or not any((wsdir / "backups").iterdir())


def test_update_on_a_full_disk_changes_nothing(tmp_path):
    """A real full file system: a small tmpfs (needs root to mount; the file-size test above covers the rest)."""
    import subprocess

    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root; test_update_that_cannot_write_a_whole_notebook_changes_nothing "
                    "covers a write cut short without it")
    kit = _kit(tmp_path)
    used = sum(p.stat().st_size for p in kit.rglob("*") if p.is_file())
    mnt = tmp_path / "small"
    mnt.mkdir()
    size_kb = (3 * used + 1_000_000) // 1024  # room for the kit and a workspace; filled up below
    if subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_kb}k", "tmpfs", str(mnt)]).returncode != 0:
        from ci import missing

        missing("cannot mount a tmpfs here (a container without CAP_SYS_ADMIN)")
    try:
        root = mnt / "kit"
        shutil.copytree(kit, root)
        wsdir = ws.ensure_workspace(root)
        _student_works(wsdir)
        _instructor_corrects(root)
        filler = mnt / "filler"
        with open(filler, "wb", buffering=0) as f:  # fill the disk but for a few kB
            try:
                while True:
                    f.write(b"\0" * 4096)
            except OSError:
                pass
        with open(filler, "r+b") as f:
            f.truncate(max(0, filler.stat().st_size - 16_384))
        before = _snapshot(wsdir)
        code, err = _cli_update(root)
        assert code == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
        assert "the disk is full: free some space" in err and "nothing was changed" in err
        assert _snapshot(wsdir) == before
        filler.unlink()
        code, err = _cli_update(root)  # space freed: the update goes through, nothing lost
        assert code in (0, 1), err
        _assert_nothing_lost(wsdir)
    finally:
        subprocess.run(["umount", "-l", str(mnt)])


# --------------------------------------------------------------------------- issue 23: seams of the update journey
def test_cells_the_student_put_above_the_first_course_cell_stay_on_top(tmp_path):
    """A note written above the notebook's title (cell 0) is the student's and stays first, after an update."""
    root = _kit(tmp_path)
    wsdir = ws.ensure_workspace(root)
    path = wsdir / "01_pinhole_projection.ipynb"
    nb = nbformat.read(str(path), as_version=4)
    title_id = nb.cells[0].get("id")
    nb.cells.insert(0, nbformat.v4.new_markdown_cell("TOP: my own summary, above the title"))
    nb.cells.insert(1, nbformat.v4.new_code_cell("top_scratch = 1"))
    nbformat.write(nb, str(path))
    _instructor_corrects(root)
    report = ws.update_workspace(root, stamp="top")
    assert report.own_cells["01_pinhole_projection.ipynb"] == 2, report.text()
    after = nbformat.read(str(path), as_version=4)
    assert [c.source for c in after.cells[:2]] == ["TOP: my own summary, above the title", "top_scratch = 1"]
    assert after.cells[2].get("id") == title_id  # and the course's title right below them


def test_a_course_cell_the_student_edited_and_the_new_course_removed_is_kept(tmp_path):
    """The instructor deletes a markdown cell the student had written into: the student's text is kept."""
    root = _kit(tmp_path)
    wsdir = ws.ensure_workspace(root)
    path = wsdir / "01_pinhole_projection.ipynb"
    nb = nbformat.read(str(path), as_version=4)
    victim = next(c for c in nb.cells if c.cell_type == "markdown" and c.get("id") != nb.cells[0].get("id")
                  and "tags" not in c.metadata)
    victim_id, mine = victim.get("id"), victim.source + "\n\nMY ANSWER: the focal length is in pixels."
    victim.source = mine
    nbformat.write(nb, str(path))
    sol = root / "solutions" / "01_pinhole_projection.ipynb"
    snb = nbformat.read(str(sol), as_version=4)
    snb.cells = [c for c in snb.cells if c.get("id") != victim_id]  # the new course drops that cell
    nbformat.write(snb, str(sol))
    rel.generate_notebooks(root / "solutions", root / "notebooks")
    assert victim_id not in {c.get("id") for c in nbformat.read(str(root / "notebooks" / path.name),
                                                                 as_version=4).cells}
    report = ws.update_workspace(root, stamp="rm")
    assert not report.ok and "no longer has" in report.text()  # said, never silent
    after = nbformat.read(str(path), as_version=4)
    kept = [c for c in after.cells if ws.KEPT_TAG in c.metadata.get("tags", [])]
    assert len(kept) == 1 and "MY ANSWER: the focal length is in pixels." in kept[0].source


def test_an_update_leaves_no_lock_file_behind(tmp_path):
    root = _kit(tmp_path)
    wsdir = ws.ensure_workspace(root)
    _student_works(wsdir)
    _instructor_corrects(root)
    ws.update_workspace(root, stamp="l1")
    assert not (wsdir / ws.LOCK).exists()
    code, err = _cli_update(root)  # and through the command
    assert code in (0, 1), err
    assert not (wsdir / ws.LOCK).exists()


def test_course_update_then_opens_the_course_with_the_options_given(tmp_path):
    """`dtscal course --update --no-browser --port N` (what `start.sh --update ...` runs) merges, then starts
    JupyterLab with those options; an update that fails opens nothing."""
    import contextlib
    import io
    from unittest import mock

    from dtscal_lib import cli

    root = _kit(tmp_path)
    wsdir = ws.ensure_workspace(root)
    _write_student_code(wsdir / "01_pinhole_projection.ipynb", "project_points", STUDENT_CODE)
    _instructor_corrects(root)
    calls = []

    def fake_exec(prog, argv):
        calls.append((prog, list(argv)))
        assert "Project world points (metres)" in _cell_of(wsdir / "01_pinhole_projection.ipynb", "project_points")
        raise SystemExit(0)  # in place of JupyterLab

    with mock.patch("dtscal_lib.paths.repo_root", return_value=root), \
            mock.patch("dtscal_lib.datasets.session_dir", return_value=tmp_path), \
            mock.patch("os.execv", fake_exec), contextlib.redirect_stdout(io.StringIO()) as out, \
            contextlib.redirect_stderr(io.StringIO()):
        with pytest.raises(SystemExit):
            cli.main(["course", "--update", "--no-browser", "--port", "8931"])
    assert len(calls) == 1, out.getvalue()
    argv = calls[0][1]
    assert "--port=8931" in argv and "--no-browser" in argv and f"--ServerApp.root_dir={wsdir}" in argv
    assert "\n".join(STUDENT_CODE) in _cell_of(wsdir / "01_pinhole_projection.ipynb", "project_points")
    assert not (wsdir / ws.LOCK).exists()

    shutil.rmtree(wsdir / "backups")
    (wsdir / "backups").write_text("not a folder")  # the next update cannot back up: nothing opens
    _instructor_corrects(root)
    calls.clear()
    with mock.patch("dtscal_lib.paths.repo_root", return_value=root), \
            mock.patch("dtscal_lib.datasets.session_dir", return_value=tmp_path), \
            mock.patch("os.execv", fake_exec), contextlib.redirect_stdout(io.StringIO()), \
            contextlib.redirect_stderr(io.StringIO()):
        code = cli.main(["course", "--update", "--no-browser", "--port", "8931"])
    assert code != 0 and calls == []


def test_update_across_the_split_of_notebook_03_keeps_the_students_code_and_adds_03b(tmp_path):
    """Issue 24 split notebook 03 in two. A workspace made from the one-piece 03 (rebuilt here: today's 03, then
    03b's cells after its own set-up, which is what the later sections were) updates to 03 + 03b: the student's
    functions and predictions stay in 03, 03b arrives new, and a later-section cell the student edited is kept
    in 03, saying it moved to 03b."""
    sol03 = nbformat.read(str(ROOT / "solutions" / "03_intrinsic_calibration.ipynb"), as_version=4)
    sol03b = nbformat.read(str(ROOT / "solutions" / "03b_calibration_quality.ipynb"), as_version=4)
    first_moved = next(i for i, c in enumerate(sol03b.cells) if c.id == "c322d105")  # the residuals cell of old 03
    before = nbformat.from_dict(dict(sol03, cells=sol03.cells + sol03b.cells[first_moved:]))
    root = tmp_path / "kit"
    (root / "solutions").mkdir(parents=True)
    nbformat.write(before, str(root / "solutions" / "03_intrinsic_calibration.ipynb"))
    rel.generate_notebooks(root / "solutions", root / "notebooks")
    wsdir = ws.ensure_workspace(root)
    path = wsdir / "03_intrinsic_calibration.ipynb"
    code = ["    return np.zeros((2, 6))  # mine"]
    _write_student_code(path, "intrinsic_constraints", code)
    nb = nbformat.read(str(path), as_version=4)
    for cell in nb.cells:
        if "predict_rank_parallel = None" in cell.source:  # a prediction cell that stays in 03
            cell.source = cell.source.replace("predict_rank_parallel = None", "predict_rank_parallel = 3")
        if cell.source.startswith("noise_px = 0.2"):  # the experiment, which moves to 03b
            cell.source = cell.source.replace("noise_px = 0.2", "noise_px = 0.5", 1)
    nb.cells.append(nbformat.v4.new_markdown_cell("my notes on the degradation tables"))
    nbformat.write(nb, str(path))

    (root / "solutions" / "03_intrinsic_calibration.ipynb").unlink()
    for p in (ROOT / "solutions").glob("03*.ipynb"):
        shutil.copyfile(p, root / "solutions" / p.name)
    rel.generate_notebooks(root / "solutions", root / "notebooks")
    report = ws.update_workspace(root, stamp="split")
    assert report.added == ["03b_calibration_quality.ipynb"]
    assert report.carried["03_intrinsic_calibration.ipynb"] == ["intrinsic_constraints"]
    assert (wsdir / "03b_calibration_quality.ipynb").read_bytes() == (
        root / "notebooks" / "03b_calibration_quality.ipynb").read_bytes()
    after = nbformat.read(str(path), as_version=4)
    sources = [c.source for c in after.cells]
    assert any(code[0] in s and "def intrinsic_constraints(" in s for s in sources)
    assert any("predict_rank_parallel = 3" in s for s in sources)
    assert "my notes on the degradation tables" in sources
    kept = [c.source for c in after.cells if ws.KEPT_TAG in c.metadata.get("tags", [])]
    assert len(kept) == 1 and "noise_px = 0.5" in kept[0] and "moved to 03b_calibration_quality.ipynb" in kept[0]
    assert any("moved to 03b_calibration_quality.ipynb" in line for line in report.kept)
    assert not any(s.startswith("noise_px = 0.2") for s in sources)  # the course's own copy is in 03b now
    assert (wsdir / "backups" / "split" / "03_intrinsic_calibration.ipynb").exists()


def test_a_practice_function_the_student_wrote_survives_an_update(tmp_path):
    """Issue 29: practice cells (the student's own functions, not graded) are the student's code like exercises."""
    root = _kit(tmp_path)
    wsdir = ws.ensure_workspace(root)
    mine = ["    return 42.0  # my own analysis"]
    _write_student_code(wsdir / "01_pinhole_projection.ipynb", "picture_difference", mine)
    sol = root / "solutions" / "01_pinhole_projection.ipynb"
    nb = nbformat.read(str(sol), as_version=4)
    nb.cells.insert(1, nbformat.v4.new_markdown_cell("A correction from your instructor."))
    nbformat.write(nb, str(sol))
    rel.generate_notebooks(root / "solutions", root / "notebooks")
    report = ws.update_workspace(root, stamp="t1")
    assert report.ok, report.text()
    assert "picture_difference" in report.carried["01_pinhole_projection.ipynb"]
    cell = _cell_of(wsdir / "01_pinhole_projection.ipynb", "picture_difference")
    assert mine[0] in cell and "def tilt_needed(" in cell and cell.count("NotImplementedError") == 1
