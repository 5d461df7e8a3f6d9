"""`dtscal handin` (`start.sh --handin`) names the zip after the student, asked once, and leaves one zip (issue 32).

On a shared lab machine git's global ``user.name`` and the login name the account (a team, "student"), not the
student: the hand-in never takes them. The name is asked on the terminal the first time, remembered in
``handin/.name``, changed by ``--name``; a hand-in under a new name replaces the old zip, so that ``handin/`` never
holds a stale one to upload by mistake. The message says how the name is changed.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import zipfile
from pathlib import Path
from unittest import mock

import pytest

from dtscal_lib.cli import main as dtscal
from dtscal_lib.errors import DtscalError
from dtscal_lib.teaching import handin


@pytest.fixture
def course(tmp_path, monkeypatch) -> Path:
    """A course folder with a workspace of two notebooks, on a machine whose git says the account's name."""
    root = tmp_path / "course"
    (root / "workspace").mkdir(parents=True)
    for name in ("01_pinhole_projection.ipynb", "02_homography.ipynb"):
        (root / "workspace" / name).write_text(json.dumps({"cells": [], "metadata": {}, "nbformat": 4,
                                                           "nbformat_minor": 5}))
    gitconfig = tmp_path / "gitconfig"
    gitconfig.write_text("[user]\n\tname = Lab Account 3\n")
    monkeypatch.setenv("GIT_CONFIG_GLOBAL", str(gitconfig))  # what a shared lab machine's git says
    monkeypatch.setenv("HOME", str(tmp_path))
    return root


def _zips(root: Path) -> list[str]:
    return sorted(p.name for p in (root / "handin").glob("*.zip"))


def test_the_name_is_asked_once_then_remembered_never_gits(course):
    asked = []
    path, names = handin.write_handin(course, ask=lambda q: asked.append(q) or "Ada Lovelace")
    assert path == course / "handin" / "Ada_Lovelace.zip" and len(asked) == 1 and "name" in asked[0].lower()
    assert names == ["01_pinhole_projection.ipynb", "02_homography.ipynb"]
    with zipfile.ZipFile(path) as z:
        assert sorted(z.namelist()) == names
    path, _ = handin.write_handin(course, ask=lambda q: pytest.fail("asked a second time"))
    assert path.name == "Ada_Lovelace.zip"  # remembered
    (course / "handin" / handin.NAME_FILE).unlink()
    with pytest.raises(DtscalError, match="--name"):  # no terminal, no name known: git's user.name is not taken
        handin.write_handin(course)
    assert not list(course.rglob("Lab_Account*"))


def test_a_new_name_replaces_the_zip_so_one_is_left(course):
    handin.write_handin(course, "Ada")
    handin.write_handin(course, "Ada Lovelace")  # the student corrects the name
    assert _zips(course) == ["Ada_Lovelace.zip"]
    handin.write_handin(course)  # the corrected name is the one remembered
    assert _zips(course) == ["Ada_Lovelace.zip"]


def test_the_message_names_the_zip_and_how_to_change_the_name(course):
    out = io.StringIO()
    with mock.patch("dtscal_lib.paths.repo_root", return_value=course), contextlib.redirect_stdout(out), \
            mock.patch("sys.stdin", io.StringIO("")):  # no terminal: the name comes from --name
        assert dtscal(["handin", "--name", "Ada Lovelace"]) == 0
    said = out.getvalue()
    assert f"wrote {course / 'handin' / 'Ada_Lovelace.zip'}" in said and '--name "Your Name"' in said, said
    assert handin.GIT_HANDIN in said  # the one git hand-in, as every text shows it
    assert os.path.isfile(course / "handin" / handin.NAME_FILE)
