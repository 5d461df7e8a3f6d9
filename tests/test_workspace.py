"""The student's workspace: created from notebooks/, and updated without losing the student's code."""

from __future__ import annotations

import shutil
from pathlib import Path

import nbformat

from dtscal_lib import release as rel
from dtscal_lib.course import workspace as ws
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
