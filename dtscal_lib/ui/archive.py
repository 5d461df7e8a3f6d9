"""SAVE of the live calibrator: the samples and the calibration in one zip, re-loadable later.

Layout of ``<name>.zip``::

    session.json                          format version, board, image size, robot, sample count
    samples.npz                           corners (n, N, 2), params (n, 4), frame_index (n,)
    camera_intrinsic/<robot>.yaml         the calibration, when there is one (Duckietown YAML)

Loading checks every part and raises :class:`~dtscal_lib.errors.DtscalError` with a message
that names the file and what is wrong; the npz is read without pickle.
"""

from __future__ import annotations

import io
import json
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import calib_files, safe_write
from ..boards import Board, CharucoBoard
from ..coverage import Sample
from ..errors import DtscalError

FORMAT = "dtscal-live-session"
VERSION = 1
#: refuse archives larger than this when unpacked (a session holds a few hundred kB)
MAX_MEMBER_BYTES = 64 * 1024 * 1024


@dataclass
class SessionArchive:
    """What a SAVE holds: ``samples`` (list of coverage.Sample), and the calibration if any."""

    board: Board
    image_size: tuple[int, int]
    robot: str
    samples: list[Sample]
    calibration: calib_files.IntrinsicCalibration | None


def save_session(path, *, board: Board, image_size, robot: str, samples, calibration=None) -> Path:
    """Write the archive atomically (:func:`dtscal_lib.safe_write.output`). Returns its path."""
    path = Path(path)
    if path.suffix.lower() != ".zip":
        path = path.with_suffix(".zip")
    robot = calib_files.check_robot_name(robot)
    n = len(samples)
    corners = np.full((n, board.n_corners, 2), np.nan)  # a ChArUco view: NaN where a corner was not seen
    for i, s in enumerate(samples):
        corners[i, slice(None) if s.ids is None else s.ids] = np.asarray(s.corners, dtype=np.float64).reshape(-1, 2)
    params = np.array([s.params for s in samples], dtype=np.float64).reshape(n, 4)
    index = np.array([s.frame_index for s in samples], dtype=np.int64).reshape(n)
    buf = io.BytesIO()
    np.savez_compressed(buf, corners=corners, params=params, frame_index=index)
    meta = {"format": FORMAT, "version": VERSION, "robot": robot, "n_samples": n,
            "board": {"cols": board.cols, "rows": board.rows, "square": board.square,
                      **({"charuco": {"marker": board.marker, "dictionary": board.dictionary, "legacy": board.legacy}}
                         if isinstance(board, CharucoBoard) else {})},
            "image_size": [int(image_size[0]), int(image_size[1])],
            "calibration": f"camera_intrinsic/{robot}.yaml" if calibration is not None else None}
    try:
        with safe_write.output(path, what="session archive") as tmp, \
                zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("session.json", json.dumps(meta, indent=1))
            z.writestr("samples.npz", buf.getvalue())
            if calibration is not None:
                with tempfile.TemporaryDirectory() as d:
                    written = calib_files.save_intrinsics(calibration, d, robot)
                    z.writestr(meta["calibration"], written.read_bytes())
    except OSError as exc:
        raise DtscalError(f"could not save the session to {path} ({exc}); choose a writable folder") from None
    return path


def _read(z: zipfile.ZipFile, name: str, where: str) -> bytes:
    try:
        info = z.getinfo(name)
    except KeyError:
        raise DtscalError(f"{where}: has no {name}; it is not a session saved by the live calibrator") from None
    if info.file_size > MAX_MEMBER_BYTES:
        raise DtscalError(f"{where}: {name} is {info.file_size} bytes unpacked, too large for a session")
    return z.read(name)


def load_session(path) -> SessionArchive:
    """Read an archive written by :func:`save_session` (checked part by part)."""
    path = Path(path)
    where = str(path)
    if not path.is_file():
        raise DtscalError(f"{where}: no such session archive; pass the .zip written by SAVE")
    try:
        with zipfile.ZipFile(path) as z:
            try:
                meta = json.loads(_read(z, "session.json", where))
            except ValueError:
                raise DtscalError(f"{where}: session.json is not valid JSON") from None
            if not isinstance(meta, dict) or meta.get("format") != FORMAT:
                raise DtscalError(f"{where}: not a dtscal live-session archive")
            if meta.get("version") != VERSION:
                raise DtscalError(f"{where}: archive version {meta.get('version')!r}; this kit reads {VERSION}")
            try:
                b = meta["board"]
                board = Board(int(b["cols"]), int(b["rows"]), float(b["square"]))
                if b.get("charuco") is not None:
                    c = b["charuco"]
                    board = CharucoBoard(board.cols, board.rows, board.square, float(c["marker"]),
                                         str(c["dictionary"]), bool(c["legacy"]))
                size = (int(meta["image_size"][0]), int(meta["image_size"][1]))
                robot = calib_files.check_robot_name(str(meta["robot"]))
            except (KeyError, TypeError, ValueError, IndexError) as exc:
                raise DtscalError(f"{where}: session.json is incomplete or malformed ({exc})") from None
            try:
                with np.load(io.BytesIO(_read(z, "samples.npz", where)), allow_pickle=False) as npz:
                    corners, params, index = npz["corners"], npz["params"], npz["frame_index"]
            except (ValueError, KeyError, OSError) as exc:
                raise DtscalError(f"{where}: samples.npz cannot be read ({exc})") from None
            n = len(index)
            seen = np.isfinite(corners).all(axis=-1) if corners.ndim == 3 else None
            partial = isinstance(board, CharucoBoard)
            if corners.shape != (n, board.n_corners, 2) or params.shape != (n, 4) or not (
                    (partial or np.all(seen)) and np.all(np.isfinite(params))):
                raise DtscalError(f"{where}: samples.npz has inconsistent shapes or non-finite values")
            calib = None
            if meta.get("calibration"):
                with tempfile.TemporaryDirectory() as d:
                    f = Path(d) / "intrinsic.yaml"
                    f.write_bytes(_read(z, str(meta["calibration"]), where))
                    try:
                        calib = calib_files.load_intrinsics(f)
                    except DtscalError as exc:
                        raise DtscalError(f"{where}: its calibration file is invalid: {exc}") from None
    except zipfile.BadZipFile:
        raise DtscalError(f"{where}: not a zip file; pass the .zip written by SAVE") from None
    if isinstance(board, CharucoBoard):
        samples = [Sample(corners[i][seen[i]].copy(), params[i].copy(), int(index[i]), np.flatnonzero(seen[i]))
                   for i in range(n)]
    else:
        samples = [Sample(corners[i].copy(), params[i].copy(), int(index[i])) for i in range(n)]
    return SessionArchive(board, size, robot, samples, calib)
