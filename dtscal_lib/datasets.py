"""The bundled recording: where it lives and how to read it.

The kit ships a SYNTHETIC recorded Duckiebot session (see ``data/README.md`` and
:mod:`dtscal_lib.synth`): two ROS 1 bags of JPEG frames and the exact ground truth.
Notebooks and tests reach it only through this module.

Where the data folder is found, first match wins:

1. the environment variable ``DTSCAL_DATA`` (a folder holding ``session/``);
2. ``data/`` beside the package, in the kit checkout (editable install);
3. ``./data`` in the current folder;
4. ``<prefix>/share/dtscal/data``: the copy a pip-installed kit carries (the wheel's data files,
   ``[tool.setuptools.data-files]`` in ``pyproject.toml``), under the environment's prefix or the
   user's base (``pip install --user``). This is how the notebooks find the recording on a
   JupyterHub, opened in place from an nbgitpuller link, with no ``DTSCAL_DATA``, checkout or workspace.

Examples
--------
>>> from dtscal_lib import datasets
>>> truth = datasets.load_truth()                       # doctest: +SKIP
>>> truth["camera"]["K"].shape                          # doctest: +SKIP
(3, 3)
>>> for index, image in datasets.intrinsic_frames(step=30):   # doctest: +SKIP
...     print(index, image.shape)
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterator

import numpy as np

from .errors import DtscalError, FrameError, SourceError
from .sources.bag import BagSource

ENV_VAR = "DTSCAL_DATA"
TRUTH_FILE = "truth.yaml"
INTRINSICS_BAG = "intrinsics.bag"
EXTRINSICS_BAG = "extrinsics.bag"
_REGENERATE = "regenerate it with `dtscal synth --out data` (about a minute)"


def _has_session(folder: Path) -> bool:
    return (folder / "session" / TRUTH_FILE).is_file()


def _installed_dirs() -> list[Path]:
    """Where ``pip install`` puts the wheel's data files: ``share/dtscal/data`` under the install schemes'
    ``data`` path (the environment's prefix, the user's base), in that order, without repeats."""
    import sys
    import sysconfig

    roots = [sysconfig.get_paths().get("data"), sys.prefix]
    try:
        roots.append(sysconfig.get_paths(f"{os.name}_user").get("data"))
    except KeyError:  # no user scheme on this platform
        pass
    out: list[Path] = []
    for r in roots:
        if r and (Path(r) / "share" / "dtscal" / "data") not in out:
            out.append(Path(r) / "share" / "dtscal" / "data")
    return out


def data_dir() -> Path:
    """The folder holding the bundled recording (it contains ``session/``).

    Raises
    ------
    DtscalError
        If ``DTSCAL_DATA`` points to a folder without a session, or no data folder is found.
    """
    env = os.environ.get(ENV_VAR)
    if env:
        folder = Path(env).expanduser()
        if not _has_session(folder):
            raise DtscalError(
                f"{ENV_VAR}={env} but {folder / 'session' / TRUTH_FILE} does not exist; point {ENV_VAR} "
                f"at a folder holding session/, unset it, or "
                f"{_REGENERATE.replace('--out data', '--out ' + str(folder))}"
            )
        return folder
    candidates = [Path(__file__).resolve().parent.parent / "data", Path.cwd() / "data", *_installed_dirs()]
    for folder in candidates:
        if _has_session(folder):
            return folder
    raise DtscalError(
        "the bundled recording was not found (looked in " + ", ".join(str(c) for c in candidates)
        + f"); {_REGENERATE}, or set {ENV_VAR} to the folder that holds session/"
    )


def session_dir() -> Path:
    """``data_dir() / "session"``: the two bags and ``truth.yaml``."""
    return data_dir() / "session"


def _arr(value, shape=None) -> np.ndarray | None:
    if value is None:
        return None
    a = np.asarray(value, dtype=np.float64)
    if shape is not None:
        a = a.reshape(shape)
    return a


def _frames_with_arrays(frames: list[dict]) -> list[dict]:
    out = []
    for f in frames:
        g = dict(f)
        g["rvec"] = _arr(f.get("rvec"), (3,))
        g["tvec"] = _arr(f.get("tvec"), (3,))
        g["corners"] = _arr(f.get("corners"), (-1, 2))
        out.append(g)
    return out


def load_truth() -> dict:
    """The ground truth of the bundled session (``session/truth.yaml``), with numpy arrays.

    Arrays: ``camera.K`` (3, 3), ``camera.dist`` (5,), ``camera.P`` (3, 4); per frame
    ``rvec``, ``tvec`` (3,) and ``corners`` (35, 2) float64 pixels, or None;
    ``extrinsics.homography`` (3, 3), ``extrinsics.homography_P`` (3, 4),
    ``extrinsics.ground_points`` (35, 2) metres.
    """
    import yaml

    path = session_dir() / TRUTH_FILE
    try:
        truth = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise DtscalError(f"{path} is not valid YAML ({exc}); {_REGENERATE}") from None
    if not isinstance(truth, dict) or not truth.get("synthetic") or "camera" not in truth:
        raise DtscalError(f"{path} does not look like the kit's truth file; {_REGENERATE}")
    cam = dict(truth["camera"])
    cam["K"] = _arr(cam["K"], (3, 3))
    cam["dist"] = _arr(cam["dist"], (-1,))
    cam["P"] = _arr(cam["P"], (3, 4))
    truth["camera"] = cam
    intr = dict(truth["intrinsics"])
    intr["frames"] = _frames_with_arrays(intr["frames"])
    truth["intrinsics"] = intr
    ext = dict(truth["extrinsics"])
    ext["frames"] = _frames_with_arrays(ext["frames"])
    ext["homography"] = _arr(ext["homography"], (3, 3))
    ext["homography_P"] = _arr(ext["homography_P"], (3, 4))
    ext["ground_points"] = _arr(ext["ground_points"], (-1, 2))
    ext["ground_to_camera_rvec"] = _arr(ext["ground_to_camera_rvec"], (3,))
    ext["ground_to_camera_tvec"] = _arr(ext["ground_to_camera_tvec"], (3,))
    truth["extrinsics"] = ext
    return truth


def read_bag_jpegs(path: Path, topic: str | None = None) -> Iterator[tuple[int, int, bytes]]:
    """``(index, stamp_ns, jpeg bytes)`` of every ``CompressedImage`` in a ROS 1 bag, in file order.

    ``index`` counts the messages of the topic from 0; ``stamp_ns`` is the header stamp.
    ``topic`` defaults to the bag's camera topic. Read by the kit's one bag reader,
    :class:`~dtscal_lib.sources.BagSource` (bounded, tolerant of damage).
    """
    path = Path(path)
    if not path.is_file():
        raise SourceError(f"bag {path} does not exist; {_REGENERATE}")
    yield from BagSource(path, topic=topic).compressed_images()


def _session_frames(name: str, step: int = 1, limit: int | None = None) -> Iterator[tuple[int, np.ndarray]]:
    """Decoded frames of a bundled bag, through the kit's one guarded decode path."""
    path = session_dir() / name
    if not path.is_file():
        raise SourceError(f"bag {path} does not exist; {_REGENERATE}")
    n = 0
    for frame in BagSource(path):
        if limit is not None and n >= limit:
            return
        if frame.index % step:
            continue
        if not frame.ok:
            raise FrameError(frame.error.reason,
                             f"frame {frame.index} of the bundled {name} cannot be used ({frame.error}); {_REGENERATE}")
        yield frame.index, frame.image
        n += 1


def intrinsic_frames(step: int = 1, limit: int | None = None) -> Iterator[tuple[int, np.ndarray]]:
    """Frames of the intrinsic sweep: ``(index, (480, 640, 3) uint8 BGR)``.

    Parameters
    ----------
    step : keep every ``step``-th frame (indices 0, step, 2*step, ...)
    limit : stop after this many frames
    """
    if int(step) < 1:
        raise DtscalError(f"step must be a positive integer, got {step}")
    if limit is not None and int(limit) < 0:
        raise DtscalError(f"limit must be >= 0 or None, got {limit}")
    yield from _session_frames(INTRINSICS_BAG, int(step), limit)


def extrinsic_frames() -> list[np.ndarray]:
    """The frames of the extrinsic capture (robot standing, board on the ground), BGR uint8."""
    return [image for _index, image in _session_frames(EXTRINSICS_BAG)]
