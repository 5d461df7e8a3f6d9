"""Helpers shared by the hand-in tests (test_grading_gradescope, test_grading_archives): a student's real
``dtscal handin`` zip, the Gradescope bundle unpacked as Gradescope does, and hand-made zip bombs."""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import struct
import subprocess
import sys
import zipfile
import zlib
from pathlib import Path

from dtscal_lib.cli import main as dtscal
from nbtools import NOTEBOOKS, SOLUTIONS


def student_handin(tmp_path: Path, name: str, solved=("01_pinhole_projection",)) -> Path:
    """A student's checkout: the notebooks ``solved`` (with the solutions' code) in workspace/, a note of theirs
    above the first cell, a backup folder; then ``dtscal handin --name NAME``. Returns the zip it wrote."""
    from unittest import mock

    import nbformat

    from dtscal_lib.teaching import release as rel
    from dtscal_lib.teaching import workspace as ws

    root = tmp_path / f"student-{name.replace(' ', '_')}"
    shutil.copytree(NOTEBOOKS, root / "notebooks")
    wsdir = ws.ensure_workspace(root)
    for stem in solved:
        nb = wsdir / f"{stem}.ipynb"
        done = rel.inject_solutions(nbformat.read(str(nb), as_version=4),
                                    nbformat.read(str(SOLUTIONS / nb.name), as_version=4))
        done.cells.insert(1, nbformat.v4.new_markdown_cell("my notes"))
        nbformat.write(done, str(nb))
        (wsdir / "backups" / "old").mkdir(parents=True, exist_ok=True)
        shutil.copyfile(nb, wsdir / "backups" / "old" / nb.name)
    out = io.StringIO()
    with mock.patch("dtscal_lib.paths.repo_root", return_value=root), contextlib.redirect_stdout(out):
        assert dtscal(["handin", "--name", name]) == 0
    z = root / "handin" / f"{name.replace(' ', '_')}.zip"
    assert f"wrote {z} with 6 notebook(s)" in out.getvalue()
    with zipfile.ZipFile(z) as zf:  # nothing of the kit, no backups: the six course notebooks at the top
        assert sorted(zf.namelist()) == sorted(p.name for p in NOTEBOOKS.glob("*.ipynb"))
    return z


def make_autograder(base: Path) -> Path:
    """The Gradescope bundle written by ``dtscal grade --gradescope-bundle``, unpacked into ``base/source``."""
    bundle = base / "autograder.zip"
    assert dtscal(["grade", "--gradescope-bundle", str(bundle)]) == 0
    root = base / "autograder"
    with zipfile.ZipFile(bundle) as z:
        names = z.namelist()
        z.extractall(root / "source")
    assert {"setup.sh", "run_autograder", "grading/cases.py", "pyproject.toml"} <= set(names)
    assert any(n.startswith("solutions/") for n in names) and any(n.startswith("dtscal_lib/grading/") for n in names)
    assert not any("__pycache__" in n for n in names)
    return root


def run_autograder(root: Path, files: dict[str, bytes]) -> dict:
    """Gradescope's run: ``files`` in ``submission/``, ``run_autograder``, then ``results/results.json``."""
    sub = root / "submission"
    if sub.exists():
        shutil.rmtree(sub)
    sub.mkdir()
    for name, data in files.items():
        (sub / name).write_bytes(data)
    env = dict(os.environ, DTSCAL_AUTOGRADER_ROOT=str(root), DTSCAL_PYTHON=sys.executable,
               PYTHONPATH=str(root / "source"))
    run = subprocess.run(["bash", str(root / "source" / "run_autograder")], env=env, capture_output=True,
                         text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    return json.loads((root / "results" / "results.json").read_text())


def bomb_zip(path: Path, member: str, unpacked: int, declared: int | None = None) -> Path:
    """A zip whose one entry ``member`` inflates to ``unpacked`` zero bytes (a multiple of 64 MiB, or less),
    written without ever holding or compressing that much: one DEFLATE block of 64 MiB of zeros, full-flushed
    (so it is independent of what precedes it), repeated. The directory declares ``declared`` bytes (default:
    the truth); a lie makes Python's zipfile stop at the declared size and fail the CRC."""
    chunk = min(unpacked, 64 * 2 ** 20)
    assert unpacked % chunk == 0
    c = zlib.compressobj(9, zlib.DEFLATED, -15)
    block = c.compress(bytes(chunk)) + c.flush(zlib.Z_FULL_FLUSH)
    data = block * (unpacked // chunk) + c.flush(zlib.Z_FINISH)
    crc = 0
    zeros = bytes(chunk)
    for _ in range(unpacked // chunk):
        crc = zlib.crc32(zeros, crc)
    size = unpacked if declared is None else declared
    name = member.encode()
    local = struct.pack("<IHHHHHIIIHH", 0x04034B50, 20, 0, 8, 0, 0, crc, len(data), size, len(name), 0) + name
    central = struct.pack("<IHHHHHHIIIHHHHHII", 0x02014B50, 20, 20, 0, 8, 0, 0, crc, len(data), size, len(name),
                          0, 0, 0, 0, 0, 0) + name
    end = struct.pack("<IHHHHIIH", 0x06054B50, 0, 0, 1, 1, len(central), len(local) + len(data), 0)
    path.write_bytes(local + data + central + end)
    return path
