"""Limits no student can move (issue 28, item 6): a notebook's cell count, the uid slots' folder,
and the grader's memory, which follows one check's answers, not the sum of a submission's."""

from __future__ import annotations

import json
import os
import pwd

from dtscal_lib.grading.grade import grade_file
from dtscal_lib.grading.loader import MAX_CELLS
from dtscal_lib.grading.material import Material
from dtscal_lib.grading.report import text
from nbtools import ROOT


def _notebook(path, cells: int):
    code = [{"cell_type": "code", "metadata": {}, "execution_count": None, "outputs": [], "source": "x = 1"}]
    path.write_text(json.dumps({"cells": code * cells, "metadata": {}, "nbformat": 4, "nbformat_minor": 5}))
    return path


def test_a_notebook_with_too_many_cells_is_refused_with_the_bound(tmp_path):
    """10,000 cells once took 75 s to grade: past MAX_CELLS the notebook is not read, and the
    student reads why (0, never a grader error)."""
    m = Material.load(ROOT)
    res = grade_file(_notebook(tmp_path / "02_homography.ipynb", MAX_CELLS + 1), m, "02_homography")
    said = text(res)
    assert f"has {MAX_CELLS + 1} cells, more than the {MAX_CELLS}" in said, said
    assert res.score == 0 and not res.grader_error
    res = grade_file(_notebook(tmp_path / "ok" / "02_homography.ipynb", MAX_CELLS) if (tmp_path / "ok").mkdir()
                     is None else None, m, "02_homography")
    assert "cells, more than" not in text(res)


def test_uid_slots_lie_where_no_other_user_can_write(tmp_path, monkeypatch):
    """Another local user who creates the temp-folder place first (world-writable, full of slot
    files) holds nothing of this grader's: its slots lie in a folder of its own user's, 0700."""
    import tempfile

    from dtscal_lib.grading import sandbox
    from unprivileged import shared_tmp

    d = sandbox._Slots.directory()
    st = os.lstat(d)
    assert st.st_uid == os.getuid() and not st.st_mode & 0o077, oct(st.st_mode)
    home = tmp_path / "not-a-folder"
    home.write_text("")
    with shared_tmp() as tmp:
        os.chmod(tmp, 0o1777)  # a temp folder: everyone writes, the sticky bit keeps each one's own
        monkeypatch.delenv("XDG_RUNTIME_DIR", raising=False)
        monkeypatch.setenv("HOME", str(home))  # no ~/.cache here: the temp folder is next
        monkeypatch.setattr(tempfile, "tempdir", str(tmp))
        squatted = tmp / f"dtscal-grade-slots-{os.getuid()}"

        squatted.mkdir()  # as another user made it: theirs (under root), open to all either way
        for k in range(64):
            (squatted / f"slot{k}").touch()
        os.chmod(squatted, 0o777)
        if os.geteuid() == 0:
            nobody = pwd.getpwnam("nobody")
            for p in [squatted, *squatted.iterdir()]:
                os.chown(p, nobody.pw_uid, nobody.pw_gid)
        d = sandbox._Slots.directory()
        assert d != squatted and os.lstat(d).st_uid == os.getuid() and not os.lstat(d).st_mode & 0o077
        run = sandbox.run_calls([("def f():\n    return 1.0", 1)],
                                [sandbox.CheckJob(id=0, calls=[("f", ())], wall=10.0, cpu=5)])
        assert float(run.checks[0].calls[0].value) == 1.0
