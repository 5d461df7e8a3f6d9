"""Class folders exported by a learning management system (Canvas, Moodle): who handed in which file.

An LMS's "download all submissions" names every file (or folder) after the student, so the grader can
give one row per student with the LMS's own id and name, grade the latest submission and list the others.
The conventions, read from the LMSs' source code:

**Canvas** (``instructure/canvas-lms``, ``app/models/content_zipper.rb``: ``get_filename`` and
``add_upload_submission``): each uploaded file is ``{name}[_LATE]_{user_id}_{file_id}_{display name}``,
where ``name`` is the student's sortable name ("Lovelace, Ada") with every non-word character removed and
lower-cased (``lovelaceada``), ``LATE`` is there when Canvas marks the submission late, ``user_id`` is the
student's Canvas id and ``file_id`` the uploaded file's (attachment's) id, which grows with every upload.
A file uploaded again under the same name gets Canvas's ``-1``, ``-2`` suffix (``handin-1.zip``). So a
student's newest file is the one with the largest file id. Some Canvas versions lower-case the whole
name, ``LATE`` included (``late``): both are read.

**Moodle** (``moodle/moodle``, ``mod/assign/classes/downloader.php``: ``get_student_prefix`` and
``load_submissionplugin_filelist``; ``mod/assign/locallib.php`` before 4.2): the prefix is the student's
full name (``_`` turned into spaces) and the participant id, ``{Full Name}_{participant id}``; with
"download submissions in folders" (the default since Moodle 3.1) each student's files lie in a folder
``{prefix}_assignsubmission_file`` (Moodle 3.1-4.1 add a trailing ``_``), otherwise each file is named
``{prefix}_assignsubmission_file_{file name}``. Moodle exports only the current attempt and marks no file
late in its name, so there is nothing to order and nothing late to report from names alone.

A class folder is read as an LMS export only when *every* hand-in in it (each notebook, .py file, zip
and folder at its top) follows one LMS's convention; any other layout keeps the grader's usual rules.
"""

from __future__ import annotations

import re
import zipfile
from dataclasses import dataclass
from pathlib import Path

#: entries of a zip looked at to tell an LMS export (a Canvas class of 300 has about 300)
MAX_NAMES = 5000

#: Canvas: name, optional LATE, user id, file id, the file's own name (``content_zipper.rb``)
CANVAS = re.compile(r"(?P<name>\w+?)(?P<late>_LATE)?_(?P<uid>\d+)_(?P<fid>\d+)_(?P<file>.+)", re.IGNORECASE)
#: Moodle: full name, participant id, the plugin's folder or prefix, the file's own name (``downloader.php``)
MOODLE = re.compile(r"(?P<name>.+?)_(?P<uid>\d+)_assignsubmission_file(?:_(?P<file>.*))?")


@dataclass(frozen=True)
class Entry:
    """One file or folder of an LMS export, read from its name."""

    path: Path
    lms: str                 #: "Canvas" or "Moodle"
    user_id: str             #: Canvas's user id, Moodle's participant id
    name: str                #: the name as the LMS wrote it (``lovelaceada``, ``Ada Lovelace``)
    order: int = 0           #: Canvas's file id (a later upload has a larger one); 0 for Moodle
    late: bool = False       #: Canvas's LATE tag
    file: str = ""           #: the file's own name as the student uploaded it ("" for a Moodle folder)

    @property
    def student(self) -> str:
        """The row's name: the LMS's name and id, so the grade goes back to the right student."""
        return f"{self.name} ({self.lms} {self.user_id})"


def _canvas(p: Path, is_dir: bool | None = None) -> Entry | None:
    m = CANVAS.fullmatch(p.name)
    if m is None or (p.is_dir() if is_dir is None else is_dir):
        return None
    return Entry(p, "Canvas", m["uid"], m["name"], int(m["fid"]), bool(m["late"]), m["file"])


def _moodle(p: Path, is_dir: bool | None = None) -> Entry | None:
    m = MOODLE.fullmatch(p.name)
    if m is None:
        return None
    if p.is_dir() if is_dir is None else is_dir:  # "download submissions in folders": the folder holds the files
        return Entry(p, "Moodle", m["uid"], m["name"].strip()) if not m["file"] else None
    return Entry(p, "Moodle", m["uid"], m["name"].strip(), file=m["file"]) if m["file"] else None


def recognise(entries: list[Path]) -> list[Entry] | None:
    """The class folder's hand-ins (its top folders and hand-in files) as one LMS's export, or None
    when not every one of them follows that LMS's naming (then the usual rules apply)."""
    if not entries:
        return None
    for read in (_canvas, _moodle):
        got = [read(p) for p in entries]
        if all(got):
            return got
    return None


def export_zip(path) -> str | None:
    """The LMS whose "download all submissions" zip ``path`` is (every entry at its top follows that LMS's
    naming), or None: such a zip is a class, never one student's hand-in."""
    try:
        with zipfile.ZipFile(path) as z:
            names = [i.filename for i in z.infolist()[:MAX_NAMES]]
    except (zipfile.BadZipFile, OSError, ValueError, EOFError):
        return None
    tops = {n.split("/", 1)[0] for n in names if n.split("/", 1)[0] not in ("", "__MACOSX")
            and not n.startswith(".")}
    entries = [Path(t) for t in sorted(tops)]
    for read in (_canvas, _moodle):
        if entries and all(read(e, any(n.startswith(e.name + "/") for n in names)) for e in entries):
            return read.__name__.strip("_").capitalize()
    return None


def newest_first(entries: list[Entry]) -> list[Entry]:
    """One student's entries, the latest upload first (Canvas's file id; then the name, for Moodle)."""
    return sorted(entries, key=lambda e: (-e.order, e.path.name))
