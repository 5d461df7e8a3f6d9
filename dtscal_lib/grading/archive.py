"""Hand-in zips, read with streamed size caps: never extracted whole, never trusted for their sizes.

A zip is one student's hand-in (``dtscal handin`` writes ``NAME.zip`` with the workspace
notebooks at its top). Only its notebooks and ``.py`` files are taken, each streamed through
a cap (:data:`MAX_MEMBER_BYTES` per member, :data:`MAX_TOTAL_BYTES` per zip,
:data:`MAX_RATIO` unpacked bytes per compressed byte), and written to the grader's private
scratch folder; everything else in the zip is listed, not read. A 2 MB zip holding a 2 GiB
notebook is refused after reading at most :data:`MAX_MEMBER_BYTES` of it: what a zip's
directory *declares* is checked first, and what its data *yields* is counted as it streams
(a zip can lie about its sizes; Fifield, "A better zip bomb", WOOT 2019, overlaps entries so
that 46 MB unpack to 4.5 PB).
"""

from __future__ import annotations

import re
import zipfile
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

from .loader import MAX_CODE_CHARS, MAX_NOTEBOOK_BYTES

#: a member notebook: the loader's own cap on a notebook file (32 MiB; the largest solution
#: notebook is 0.59 MB); a member .py file: the loader's cap on code (256 kB)
MAX_MEMBER_BYTES = MAX_NOTEBOOK_BYTES
#: all members taken from one zip together: the seven course notebooks at the member cap would
#: be 224 MiB; a real hand-in of the six solutions (before 03b) unpacked to 1.8 MB
MAX_TOTAL_BYTES = 64 * 2 ** 20
#: the zip file itself (its central directory is read whole by Python's zipfile)
MAX_ZIP_BYTES = 64 * 2 ** 20
#: entries listed per zip; ``dtscal handin`` writes 6
MAX_ENTRIES = 2000
#: unpacked bytes per compressed byte, above MIN_RATIO_BYTES: the course notebooks compress
#: 1.3x-2.8x with DEFLATE (measured on solutions/*.ipynb); Sonar's rule S5042 on zip bombs
#: suggests flagging ratios above 10-100; a zip bomb's members reach 1000x (DEFLATE's limit
#: is 1032x) and more when overlapped
MAX_RATIO = 100
MIN_RATIO_BYTES = 2 ** 20
CHUNK = 64 * 1024
CODE = (".ipynb", ".py")


@dataclass
class Member:
    """One notebook or .py file taken from a zip: where it was written, and its name in the zip."""

    name: str
    path: Path


@dataclass
class Unpacked:
    """What a zip gave: the members taken, and a note for every entry not taken (and why)."""

    members: list[Member] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def safe_parts(name: str) -> list[str]:
    """An entry name as path parts that stay inside a folder (no ``..``, no root, no drive)."""
    parts = []
    for part in PurePosixPath(name.replace("\\", "/")).parts:
        part = re.sub(r"[\x00-\x1f:]", "_", part)
        if part in ("", ".", "..", "/") or part.endswith(":"):
            continue
        parts.append(part[:120])
    return parts


class _TooBig(Exception):
    pass


def _stream(z: zipfile.ZipFile, info: zipfile.ZipInfo, out: Path, cap: int) -> int:
    """Copy one member to ``out`` through the caps; returns the bytes written."""
    limit_ratio = max(MIN_RATIO_BYTES, MAX_RATIO * max(info.compress_size, 1))
    n = 0
    with z.open(info) as src, open(out, "wb") as dst:
        while True:
            chunk = src.read(CHUNK)
            if not chunk:
                break
            n += len(chunk)
            if n > cap:
                raise _TooBig(f"it unpacks to more than {cap / 2 ** 20:g} MB")
            if n > limit_ratio:
                raise _TooBig(f"it unpacks to more than {MAX_RATIO}x its compressed size (a zip bomb?)")
            dst.write(chunk)
    return n


def read_zip(path, into) -> Unpacked:
    """Take the notebooks and .py files of the zip at ``path`` into the folder ``into``.

    Never raises on a bad zip: the reason goes into the notes (the student then gets a row
    saying why nothing was graded)."""
    path, into = Path(path), Path(into)
    res = Unpacked()
    label = path.name
    try:
        size = path.stat().st_size
    except OSError as exc:
        res.notes.append(f"{label}: cannot be read ({exc.strerror or exc}); not graded")
        return res
    if size > MAX_ZIP_BYTES:
        res.notes.append(f"{label}: the zip is {size / 2 ** 20:.1f} MB, more than the {MAX_ZIP_BYTES / 2 ** 20:g} MB "
                         "a hand-in may have; not graded (hand in the notebooks only: dtscal handin)")
        return res
    total = 0
    try:
        with zipfile.ZipFile(path) as z:
            infos = z.infolist()
            if len(infos) > MAX_ENTRIES:
                res.notes.append(f"{label}: {len(infos)} entries, more than the {MAX_ENTRIES} a hand-in may have; "
                                 "not graded (hand in the notebooks only: dtscal handin)")
                return res
            used: set[str] = set()
            skipped = []
            for info in infos:
                parts = safe_parts(info.filename)
                if info.is_dir() or not parts:
                    continue
                rel = "/".join(parts)
                shown = f"{label}/{rel}"
                if any(p.startswith(".") or p in ("__pycache__", "__MACOSX") for p in parts):
                    continue  # hidden files, editor and OS droppings
                if not parts[-1].lower().endswith(CODE):
                    skipped.append(shown)
                    continue
                cap = MAX_CODE_CHARS if parts[-1].lower().endswith(".py") else MAX_MEMBER_BYTES
                if info.file_size > cap:
                    res.notes.append(f"{shown}: {info.file_size / 2 ** 20:.1f} MB unpacked, more than the "
                                     f"{cap / 2 ** 20:g} MB a submission may have; not graded")
                    continue
                if total + info.file_size > MAX_TOTAL_BYTES:
                    res.notes.append(f"{shown}: the zip's files together exceed {MAX_TOTAL_BYTES / 2 ** 20:g} MB; "
                                     "not graded")
                    continue
                key = rel.lower()
                k = 1
                while key in used:  # two entries that differ only in case or in dropped parts
                    k += 1
                    key = f"{rel.lower()}~{k}"
                used.add(key)
                out = into.joinpath(*parts[:-1], parts[-1] if k == 1 else f"{k}_{parts[-1]}")
                out.parent.mkdir(parents=True, exist_ok=True)
                try:
                    total += _stream(z, info, out, min(cap, MAX_TOTAL_BYTES - total))
                except _TooBig as exc:
                    out.unlink(missing_ok=True)
                    res.notes.append(f"{shown}: not graded: {exc}")
                    continue
                except (zipfile.BadZipFile, zipfile.LargeZipFile, NotImplementedError, RuntimeError, EOFError,
                        ValueError, OSError) as exc:  # bad CRC, encrypted, unknown compression, truncated
                    out.unlink(missing_ok=True)
                    res.notes.append(f"{shown}: cannot be unpacked ({type(exc).__name__}: {str(exc)[:200]}); "
                                     "not graded")
                    continue
                res.members.append(Member(rel, out))
            if skipped:
                head = ", ".join(skipped[:5]) + (f" and {len(skipped) - 5} more" if len(skipped) > 5 else "")
                res.notes.append(f"{head}: not a notebook (.ipynb) or .py file; not graded")
    except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, ValueError, EOFError) as exc:
        res.notes.append(f"{label}: not a readable zip ({type(exc).__name__}: {str(exc)[:200]}); not graded — ask "
                         "the student for the file `dtscal handin` wrote")
    return res
