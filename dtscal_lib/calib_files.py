"""Duckietown calibration files: read, validate and write them safely.

A Duckiebot keeps its camera calibration in its config folder ``calibrations/``:

* ``camera_intrinsic/<ROBOT>.yaml``: a ROS ``CameraInfo`` YAML exactly as
  ``camera_calibration_parsers`` writes it (``image_width``, ``image_height``,
  ``camera_name``, ``camera_matrix``, ``distortion_model``, ``distortion_coefficients``,
  ``rectification_matrix``, ``projection_matrix``; every matrix as ``{rows, cols, data}``).
* ``camera_extrinsic/<ROBOT>.yaml``: ``homography: [h11, ..., h33]``, the row-major
  ground homography from *rectified* pixels to ground metres (robot frame, x forward,
  y left).

Beside each ``<ROBOT>.yaml`` sits the factory ``default.yaml``, which the robot falls
back to and which is never overwritten (:func:`write_defaults` only creates it when it
is missing).

Reading uses ``yaml``'s safe loader only, with limits (:mod:`dtscal_lib.safe_yaml`: file
size, alias expansion, number length, duplicate keys): a file with a Python tag
(``!!python/object/apply:...``) is refused, nothing in it runs. Every value is checked
(finite numbers, matrix sizes, a plausible ``K``, a rotation ``R``, a ``P`` of the form
``[K' | t]``, a non-singular, non-corrupt homography) and every error names the file and
the field.

Writing is atomic: the new content goes to a temporary file in the same folder, is
flushed and fsync'ed, and replaces ``<ROBOT>.yaml`` with ``os.replace``. The previous
``<ROBOT>.yaml`` is kept as ``<ROBOT>.yaml.bak`` (the last one only). A failed write
leaves the previous file as it was and removes the temporary file. A target that is a device
or a FIFO is written through, never replaced (:mod:`dtscal_lib.safe_write`).

Examples
--------
>>> import tempfile
>>> from dtscal_lib import duckietown as dt
>>> d = tempfile.mkdtemp()
>>> paths = write_defaults(d)
>>> calib = load_intrinsics(intrinsic_path(d, "default"))
>>> calib.to_dict() == dt.DEFAULT_INTRINSICS
True
"""

from __future__ import annotations

import math
import os
import re
import shutil
import time
import warnings
from dataclasses import FrozenInstanceError
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from . import duckietown as dt
from . import safe_write, safe_yaml
from .camera import CameraModel, as_model_dist, rectification_maps, undistort_pixels
from .errors import CalibrationFileError, CalibrationFileWarning, DtscalError

#: distortion models a file may declare, with their number of coefficients: ROS's calibrator
#: (camera_calibration calibrator.py) writes plumb_bob with 5, rational_polynomial with 8 (OpenCV's
#: CALIB_RATIONAL_MODEL, ``dist_coeffs.flat[:8]``) and equidistant with 4 (``cv2.fisheye.calibrate``)
SUPPORTED_MODELS = {"plumb_bob": 5, "rational_polynomial": 8, "equidistant": 4}
#: the coefficient names of each model, in the file's order
_COEFF_NAMES = {"plumb_bob": "[k1, k2, p1, p2, k3]", "rational_polynomial": "[k1, k2, p1, p2, k3, k4, k5, k6]",
                "equidistant": "[k1, k2, k3, k4]"}
#: ROS models recognised but not supported here, with what to do instead
_UNSUPPORTED_MODELS: dict[str, str] = {}
#: order of the keys in a ROS CameraInfo YAML (as the shipped default.yaml)
INTRINSIC_KEYS = ("image_width", "image_height", "camera_name", "camera_matrix", "distortion_model",
                  "distortion_coefficients", "rectification_matrix", "projection_matrix")

#: the one robot-name rule (files, topics, COMMIT, ``ros:NAME``): a Duckiebot's name is a component of its ROS
#: topics ``/NAME/camera_node/...``, and ROS names hold letters, digits and underscores only (ROS wiki, "Names":
#: "subsequent characters can be alphanumeric ([0-9|a-z|A-Z]), underscores (_)")
ROBOT_NAME = re.compile(r"[A-Za-z0-9_]+")
#: longest robot name: a hostname label (Duckiebots are named by their hostname); the
#: kit's longest file name for it, the backup's temporary ``.NAME.rejected.yaml.bak.XXXXXXXX.tmp``,
#: then stays far below every filesystem's 255-byte limit
MAX_ROBOT_NAME = 63
#: ``NAME.rejected.yaml`` keeps a refused calibration beside ``NAME.yaml`` (``--keep-anyway``)
REJECTED_SUFFIX = ".rejected"
# tolerances of the plausibility checks
_ROT_TOL = 1e-6
_MAX_SKEW_RATIO = 0.05   # |s| / fx
_MAX_ASPECT = 5.0        # max(fx/fy, fy/fx)


# --------------------------------------------------------------------------- paths
def is_robot_name(name) -> bool:
    """True for a Duckiebot's name by the one rule (:data:`ROBOT_NAME`)."""
    return isinstance(name, str) and ROBOT_NAME.fullmatch(name) is not None


def check_robot_name(robot: str) -> str:
    """Validate a robot name for writing its calibration; returns it (``default`` is refused)."""
    if not isinstance(robot, str) or not robot:
        raise CalibrationFileError(f"robot name must be a non-empty string, got {robot!r}; pass --robot NAME")
    if robot.lower() == dt.DEFAULT_NAME:  # default.yaml, also on a case-insensitive filesystem
        raise CalibrationFileError(
            f"--robot {robot}: default.yaml is the factory calibration and is never overwritten; pass --robot NAME "
            "(robot names are compared ignoring case)"
        )
    if len(robot) > MAX_ROBOT_NAME:
        raise CalibrationFileError(
            f"robot name {robot[:20]}... has {len(robot)} characters; at most {MAX_ROBOT_NAME} (a hostname) are "
            "allowed, so that the file, its backup and their temporary names fit the filesystem: pass a "
            "shorter --robot NAME"
        )
    if robot.lower().endswith(REJECTED_SUFFIX):
        raise CalibrationFileError(
            f"--robot {robot}: names ending in {REJECTED_SUFFIX!r} are kept for refused calibrations "
            f"(NAME{REJECTED_SUFFIX}.yaml); pass the robot's own name"
        )
    if not is_robot_name(robot):
        raise CalibrationFileError(
            f"robot name {robot[:80]!r} is not valid: a Duckiebot's name has letters, digits and '_' only (it names "
            f"its ROS topics {dt.ros_name(dt.CAMERA_NODE, 'NAME')}/...), e.g. --robot autobot01"
        )
    return robot


def _file_name(robot: str) -> str:
    if robot == dt.DEFAULT_NAME:
        return f"{robot}.yaml"
    return f"{check_robot_name(robot)}.yaml"


def intrinsic_path(out_dir, robot: str) -> Path:
    """``out_dir/camera_intrinsic/<robot>.yaml`` (``out_dir`` is the robot's ``calibrations/``).

    ``robot`` may be ``"default"`` here (to read the factory file); it may not contain
    path separators.
    """
    return Path(out_dir) / "camera_intrinsic" / _file_name(robot)


def extrinsic_path(out_dir, robot: str) -> Path:
    """``out_dir/camera_extrinsic/<robot>.yaml`` (``out_dir`` is the robot's ``calibrations/``)."""
    return Path(out_dir) / "camera_extrinsic" / _file_name(robot)


# --------------------------------------------------------------------------- field validation
def _fail(where: str, msg: str) -> CalibrationFileError:
    if len(msg) > 600:  # a hostile value must not make an unreadable (or huge) message
        msg = f"{msg[:450]} … {msg[-120:]}"
    return CalibrationFileError(f"{where}: {msg}")


def _is_int(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _number(x, where: str, field: str) -> float:
    """One finite number from YAML; strings, bools, null, NaN and inf are refused."""
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        hint = ""
        if isinstance(x, str):
            try:
                float(x)
                hint = (" (YAML 1.1 reads a number such as 1e-05 without a '.' in the mantissa as text; "
                        "write it as 1.0e-05, unquoted)")
            except ValueError:
                hint = "; write a plain number, unquoted"
        raise _fail(where, f"{field} is {type(x).__name__} {x!r}, expected a number{hint}")
    v = float(x)
    if not math.isfinite(v):
        raise _fail(where, f"{field} is {x!r}; every value must be a finite number (NaN/inf usually mean "
                           "the calibration failed: recalibrate)")
    return v


def _matrix(doc: dict, key: str, rows: int, cols: int | None, where: str) -> np.ndarray:
    """A ``{rows, cols, data}`` matrix of the ROS layout, (rows, cols) float64."""
    if key not in doc:
        raise _fail(where, f"missing field {key!r} (a ROS CameraInfo YAML has {', '.join(INTRINSIC_KEYS)})")
    m = doc[key]
    if not isinstance(m, dict):
        raise _fail(where, f"{key} must be a mapping with rows, cols and data, got {type(m).__name__}")
    for sub in ("rows", "cols", "data"):
        if sub not in m:
            raise _fail(where, f"{key} has no {sub!r}; expected rows, cols and data")
    r, c, data = m["rows"], m["cols"], m["data"]
    for name, val in (("rows", r), ("cols", c)):
        if not _is_int(val) or val <= 0:
            raise _fail(where, f"{key}.{name} is {val!r}, expected a positive integer")
    if r != rows or (cols is not None and c != cols):
        want = f"{rows}x{cols}" if cols is not None else f"{rows} row(s)"
        raise _fail(where, f"{key} is {r}x{c}, expected {want}")
    if not isinstance(data, list):
        raise _fail(where, f"{key}.data must be a list of numbers, got {type(data).__name__}")
    if len(data) != r * c:
        raise _fail(where, f"{key}.data has {len(data)} values; expected rows*cols = {r * c}")
    vals = [_number(v, where, f"{key}.data[{i}]") for i, v in enumerate(data)]
    return np.array(vals, dtype=np.float64).reshape(r, c)


def _warn(where: str, msg: str) -> None:
    warnings.warn(CalibrationFileWarning(f"{where}: {msg}"), stacklevel=3)


def _read_P(P: np.ndarray, where: str) -> np.ndarray:
    """``P`` as Duckietown's loader uses it: a third row ``[0, 0, 1, t]`` with ``t != 0`` is read as
    ``[0, 0, 1, 0]``, with a :class:`~dtscal_lib.errors.CalibrationFileWarning`.

    Duckietown's camera node and rectifier pass only P's left 3x3 (the rectified camera matrix)
    to OpenCV, so the fourth entry of the third row is never used; real files carry ``1`` there
    (Duckietown's DD24 extrinsic calibration YAML has ``[0, 0, 1, 1]``). A third row whose first
    three entries are not ``[0, 0, 1]`` changes the rectified camera itself and stays an error.
    """
    if P.shape == (3, 4) and np.all(np.isfinite(P)) and np.array_equal(P[2, :3], [0.0, 0.0, 1.0]) and P[2, 3] != 0:
        _warn(where, f"projection_matrix third row is {P[2].tolist()}, not [0, 0, 1, 0]; read as [0, 0, 1, 0] "
                     "as Duckietown's loader does (only P's left 3x3, the rectified camera matrix, is used). "
                     "Recalibrate or fix the file to silence this warning")
        P = P.copy()
        P[2, 3] = 0.0
    return P


def _check_intrinsic_values(width, height, K, model, D, R, P, where: str) -> None:
    """Plausibility of already-parsed intrinsic values; raises CalibrationFileError."""
    for name, val in (("image_width", width), ("image_height", height)):
        if not _is_int(val) or val <= 0:
            raise _fail(where, f"{name} is {val!r}, expected a positive integer (pixels)")
    if K.shape != (3, 3) or not np.all(np.isfinite(K)):
        raise _fail(where, "camera_matrix must be a finite 3x3 matrix")
    fx, s, cx, fy, cy = K[0, 0], K[0, 1], K[0, 2], K[1, 1], K[1, 2]
    if fx <= 0 or fy <= 0:
        raise _fail(where, f"camera_matrix has fx = {fx:g}, fy = {fy:g}; focal lengths must be positive "
                           "(data = [fx, s, cx, 0, fy, cy, 0, 0, 1])")
    if max(fx / fy, fy / fx) > _MAX_ASPECT:
        raise _fail(where, f"camera_matrix has fx = {fx:g} and fy = {fy:g}, an aspect ratio beyond "
                           f"{_MAX_ASPECT:g}; not a plausible camera: recalibrate")
    if K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
        raise _fail(where, "camera_matrix must look like [fx, s, cx, 0, fy, cy, 0, 0, 1]; "
                           f"its data is {K.ravel().tolist()}")
    if not (0 <= cx <= width and 0 <= cy <= height):
        raise _fail(where, f"camera_matrix principal point ({cx:g}, {cy:g}) lies outside the "
                           f"{width}x{height} image; check image_width/image_height or recalibrate")
    if abs(s) > _MAX_SKEW_RATIO * fx:
        raise _fail(where, f"camera_matrix skew s = {s:g} is implausibly large (|s| > {_MAX_SKEW_RATIO:g} fx); "
                           "real cameras have s close to 0: recalibrate")
    if model in _UNSUPPORTED_MODELS:
        raise _fail(where, f"distortion_model {model!r} is not supported: {_UNSUPPORTED_MODELS[model]}")
    if model not in SUPPORTED_MODELS:
        raise _fail(where, f"distortion_model is {model!r}; expected one of {sorted(SUPPORTED_MODELS)}")
    n = SUPPORTED_MODELS[model]
    if D.shape != (n,) or not np.all(np.isfinite(D)):
        raise _fail(where, f"distortion_coefficients has {D.size} values; {model} needs {n} "
                           f"{_COEFF_NAMES[model]}")
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise _fail(where, "rectification_matrix must be a finite 3x3 matrix")
    ortho = np.abs(R @ R.T - np.eye(3)).max()
    det = np.linalg.det(R)
    if ortho > _ROT_TOL or abs(det - 1) > _ROT_TOL:
        raise _fail(where, f"rectification_matrix is not a rotation (|R R^T - I| = {ortho:.3g}, det = {det:.9g}; "
                           "both must be within 1e-6 of a rotation's); a single camera uses the identity")
    if P.shape != (3, 4) or not np.all(np.isfinite(P)):
        raise _fail(where, "projection_matrix must be a finite 3x4 matrix")
    if not np.array_equal(P[2], [0.0, 0.0, 1.0, 0.0]):
        raise _fail(where, f"projection_matrix third row is {P[2].tolist()}; expected [0, 0, 1, 0] "
                           "(P = [K' | t] with K' the rectified camera matrix)")
    if P[0, 0] <= 0 or P[1, 1] <= 0:
        raise _fail(where, f"projection_matrix has fx' = {P[0, 0]:g}, fy' = {P[1, 1]:g}; "
                           "they must be positive")


# --------------------------------------------------------------------------- intrinsics
class IntrinsicCalibration(CameraModel):
    """The content of a ``camera_intrinsic/<ROBOT>.yaml`` file, validated: a :class:`CameraModel` with a name.

    The kit has one camera type, :class:`~dtscal_lib.camera.CameraModel` (``K``, ``dist``,
    ``size``, ``model``, ``P``). A calibration file is that camera plus what only the file
    holds: the ``camera_name`` and the rectification rotation ``R``. So an
    ``IntrinsicCalibration`` *is* a ``CameraModel`` (it projects, undistorts and rectifies,
    honouring ``R``), built from the file's fields in the file's order and checked as strictly
    as a file is read (every error names the field).

    Attributes
    ----------
    camera_name : str
    width, height : int, image size in pixels (``size`` is ``(width, height)``)
    K : (3, 3) float64 camera matrix ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``
    distortion_model : str, ``"plumb_bob"`` (the camera's ``model``)
    D : (5,) float64 ``[k1, k2, p1, p2, k3]`` (the camera's ``dist``)
    R : (3, 3) float64 rectification rotation (identity for a single camera)
    P : (3, 4) float64 projection matrix ``[K' | t]`` of the rectified image

    Every array is read-only.
    """

    camera_name: str
    R: np.ndarray

    def __init__(self, camera_name: str, width: int, height: int, K, distortion_model: str, D, R, P):
        where = f"IntrinsicCalibration({camera_name!r})"
        if not isinstance(camera_name, str):
            raise _fail(where, f"camera_name must be a string, got {type(camera_name).__name__}")
        arrays = {}
        for name, value, shape in (("K", K, (3, 3)), ("D", D, None), ("R", R, (3, 3)), ("P", P, (3, 4))):
            try:
                a = np.array(value, dtype=np.float64)
            except (TypeError, ValueError):
                raise _fail(where, f"{name} must be numeric") from None
            if name == "D":
                a = a.ravel()
            if shape is not None and a.shape != shape:
                raise _fail(where, f"{name} must have shape {shape}, got {a.shape}")
            if not np.all(np.isfinite(a)):
                raise _fail(where, f"{name} contains NaN or infinite values")
            arrays[name] = a
        _check_intrinsic_values(width, height, arrays["K"], distortion_model,
                                arrays["D"], arrays["R"], arrays["P"], where)
        for name, value in (("K", arrays["K"]), ("dist", arrays["D"]), ("size", (width, height)),
                            ("model", distortion_model), ("P", arrays["P"]), ("camera_name", camera_name),
                            ("R", arrays["R"])):
            object.__setattr__(self, name, value)
        try:
            self.__post_init__()  # the camera's own checks and normal form (K, dist, size, P)
        except DtscalError as e:
            raise _fail(where, str(e)) from e
        for name in ("K", "dist", "P", "R"):
            getattr(self, name).setflags(write=False)

    def __repr__(self) -> str:
        return (f"IntrinsicCalibration(camera_name={self.camera_name!r}, width={self.width}, "
                f"height={self.height}, K={self.K.tolist()}, distortion_model={self.model!r}, "
                f"D={self.D.tolist()}, R={self.R.tolist()}, P={self.P.tolist()})")

    def __eq__(self, other):
        if not isinstance(other, IntrinsicCalibration):
            return NotImplemented
        return (self.camera_name == other.camera_name and self.size == other.size and self.model == other.model
                and all(np.array_equal(getattr(self, n), getattr(other, n)) for n in "KDRP"))

    __hash__ = None  # arrays inside: not hashable

    def __setattr__(self, name, value):
        raise FrozenInstanceError(f"cannot assign to field {name!r}")

    def __delattr__(self, name):
        raise FrozenInstanceError(f"cannot delete field {name!r}")

    # the file's names for the camera's fields
    @property
    def width(self) -> int:
        return self.size[0]

    @property
    def height(self) -> int:
        return self.size[1]

    @property
    def D(self) -> np.ndarray:
        """The camera's ``dist``: ``[k1, k2, p1, p2, k3]`` (plumb_bob), 8 values (rational_polynomial) or 4
        (equidistant), as the file's ``distortion_coefficients``."""
        return self.dist

    @property
    def distortion_model(self) -> str:
        return self.model

    # the rectified image honours R (a plain CameraModel has none)
    def undistort_pixels(self, uv, rectified: bool = True) -> np.ndarray:
        """Distorted pixels -> rectified pixels (``rectified=True``, through ``R`` and ``P``) or normalized."""
        if not rectified:
            return undistort_pixels(uv, self.K, self.dist, model=self.model)
        return undistort_pixels(uv, self.K, self.dist, R=self.R, P=self.P, model=self.model)

    def rectification_maps(self, new_K=None, size=None):
        return rectification_maps(self.K, self.dist, self.rectified_K if new_K is None else new_K,
                                  self.size if size is None else size, self.R, model=self.model)

    def opencv_maps(self, R=None):
        return super().opencv_maps(self.R if R is None else R)

    def camera(self) -> CameraModel:
        """This camera as a plain :class:`~dtscal_lib.camera.CameraModel` (``P`` as stored, no name).

        Raises
        ------
        CalibrationFileError
            If ``R`` is not the identity: a plain :class:`CameraModel` describes a single camera
            without a rectification rotation, as every Duckiebot file has.
        """
        if not np.allclose(self.R, np.eye(3), atol=1e-9, rtol=0):
            raise CalibrationFileError(
                f"camera {self.camera_name!r}: rectification_matrix is not the identity (a stereo "
                "rectification); dtscal's camera model handles single cameras only"
            )
        return CameraModel(self.K, self.dist, self.size, self.model, self.P)

    def to_dict(self) -> dict:
        """The ROS ``CameraInfo`` YAML layout, keys in the order of the shipped ``default.yaml``.

        Integral values are written as ints (``0``, ``1``) as ROS does; other values as
        Python floats, which ``yaml.safe_dump`` writes with ``repr`` and so round-trip exactly.
        """
        def mat(a: np.ndarray) -> dict:
            a = np.atleast_2d(a)
            return {"rows": int(a.shape[0]), "cols": int(a.shape[1]), "data": [_plain(v) for v in a.ravel()]}

        return {
            "image_width": int(self.width),
            "image_height": int(self.height),
            "camera_name": self.camera_name,
            "camera_matrix": mat(self.K),
            "distortion_model": self.distortion_model,
            "distortion_coefficients": mat(self.D.reshape(1, -1)),
            "rectification_matrix": mat(self.R),
            "projection_matrix": mat(self.P),
        }

    @classmethod
    def from_camera(cls, camera: CameraModel, camera_name: str) -> "IntrinsicCalibration":
        """The file content for a calibrated camera: ``R = I``, ``P = camera.P``.

        A ``radial2`` camera is written as ``plumb_bob`` with ``p1 = p2 = k3 = 0``; rational_polynomial
        and equidistant keep their model and their 8 or 4 coefficients.
        """
        if not isinstance(camera, CameraModel):
            raise CalibrationFileError(f"from_camera needs a CameraModel, got {type(camera).__name__}")
        w, h = camera.size
        model = "plumb_bob" if camera.model == "radial2" else camera.model
        return cls(str(camera_name), int(w), int(h), camera.K, model, as_model_dist(camera.dist, model),
                   np.eye(3), camera.P)

    @classmethod
    def from_dict(cls, doc: Any, where: str = "<dict>") -> "IntrinsicCalibration":
        """Validate a parsed ROS ``CameraInfo`` YAML mapping; ``where`` names it in errors."""
        if not isinstance(doc, dict):
            raise _fail(where, f"expected a mapping of ROS CameraInfo fields, got {type(doc).__name__}")
        missing = [k for k in INTRINSIC_KEYS if k not in doc]
        if missing:
            raise _fail(where, f"missing field(s) {', '.join(missing)}; a ROS CameraInfo YAML has "
                               f"{', '.join(INTRINSIC_KEYS)}")
        width, height = doc["image_width"], doc["image_height"]
        for name, val in (("image_width", width), ("image_height", height)):
            if not _is_int(val) or val <= 0:
                raise _fail(where, f"{name} is {val!r}, expected a positive integer (pixels)")
        name = doc["camera_name"]
        if not isinstance(name, str):
            raise _fail(where, f"camera_name is {name!r}, expected a string")
        model = doc["distortion_model"]
        if not isinstance(model, str):
            raise _fail(where, f"distortion_model is {model!r}, expected a string such as plumb_bob")
        if model in _UNSUPPORTED_MODELS:
            raise _fail(where, f"distortion_model {model!r} is not supported: {_UNSUPPORTED_MODELS[model]}")
        if model not in SUPPORTED_MODELS:
            raise _fail(where, f"distortion_model is {model!r}; expected one of {sorted(SUPPORTED_MODELS)}")
        K = _matrix(doc, "camera_matrix", 3, 3, where)
        D = _matrix(doc, "distortion_coefficients", 1, None, where).ravel()  # its length: checked below, by model
        R = _matrix(doc, "rectification_matrix", 3, 3, where)
        P = _read_P(_matrix(doc, "projection_matrix", 3, 4, where), where)
        _check_intrinsic_values(width, height, K, model, D, R, P, where)
        return cls(name, width, height, K, model, D, R, P)


def _plain(v: float) -> int | float:
    """A float as YAML should see it: an int when integral (and not -0.0), else a float."""
    v = float(v)
    if v.is_integer() and abs(v) < 2**53 and not (v == 0 and math.copysign(1.0, v) < 0):
        return int(v)
    return v


# --------------------------------------------------------------------------- reading
def _read_yaml(path) -> tuple[Any, str]:
    p = Path(path)
    where = str(p)
    if not p.exists():
        raise _fail(where, "file not found; check the robot name and the calibrations folder "
                           "(it holds camera_intrinsic/ and camera_extrinsic/)")
    try:  # bounded: file size, alias expansion, number lengths, duplicate keys (see safe_yaml)
        doc = safe_yaml.load_yaml_file(p, where)
    except yaml.constructor.ConstructorError as e:
        problem = getattr(e, "problem", "") or ""
        if "constructor for the tag" not in problem:
            raise _fail(where, f"is not valid calibration YAML: {problem}; fix the file or restore it "
                               "from default.yaml") from None
        tag = safe_yaml.shorten(problem.split("tag", 1)[1].strip(), 80)
        raise _fail(where, f"contains a non-data tag ({tag}) and was not loaded (nothing in it was run); "
                           "a calibration file holds only numbers, strings, lists and mappings. Do not use "
                           "this file: restore it from default.yaml or recalibrate") from None
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = safe_yaml.shorten(getattr(e, "problem", None) or str(e).splitlines()[0], 200)
        raise _fail(where, f"is not valid YAML{at}: {problem}; fix the file or restore it "
                           "from default.yaml") from None
    if doc is None:
        raise _fail(where, "is empty; restore it from default.yaml or recalibrate")
    if not isinstance(doc, dict):
        raise _fail(where, f"must be a YAML mapping (key: value lines), got a {type(doc).__name__}")
    return doc, where


def load_intrinsics(path) -> IntrinsicCalibration:
    """Read and validate a ``camera_intrinsic/<ROBOT>.yaml`` (ROS CameraInfo YAML).

    Raises
    ------
    CalibrationFileError
        Naming the file and the field: missing file, YAML syntax error, a non-data
        (Python) tag, missing fields, wrong sizes, non-numbers, NaN/inf, implausible
        ``K``, unknown distortion model, non-rotation ``R``, malformed ``P``.
    """
    doc, where = _read_yaml(path)
    calib = IntrinsicCalibration.from_dict(doc, where)
    _warn_outside_profile(calib, where)
    return calib


def _warn_outside_profile(calib: "IntrinsicCalibration", where: str) -> None:
    """One line when the file's focal lengths lie outside those of the real robots of its kind (portrait
    frames: the DD24's, else the Duckiebot's fleet; :mod:`dtscal_lib.profiles`): loaded, but named."""
    from .profiles import profile_for_image

    prof = profile_for_image(calib.width, calib.height)
    lo, hi = prof.fx_per_width
    fx, fy = float(calib.K[0, 0]), float(calib.K[1, 1])
    if not all(lo <= f / calib.width <= hi for f in (fx, fy)):
        _warn(where, f"fx {fx:.0f} / fy {fy:.0f} px at {calib.width} px wide lie outside every real {prof.name}'s "
                     f"camera ({lo * calib.width:.0f}-{hi * calib.width:.0f} px): another camera, or a calibration to "
                     "redo")


def validate_homography(H, where: str = "homography", *, writing: bool = False,
                        corrupt_rule: bool = True) -> np.ndarray:
    """Check a ground homography (rectified pixel -> ground metres); returns (3, 3) float64.

    Refuses non-finite and singular homographies with a :class:`CalibrationFileError` naming
    ``where``. ``H[1][2] > 0`` is Duckietown's rule when *writing* a file (``writing=True``:
    refused); its reader accepts such files, and so does the kit, with a
    :class:`~dtscal_lib.errors.CalibrationFileWarning`: among the calibration files of about 125 real
    Duckiebots in Duckietown's public fleet repository (duckiefleet, 2017-18), 8 well-formed extrinsic
    files have it (issue 17's survey), robots whose image is
    rotated 180 degrees (the camera mounted upside-down), whose own ``P`` gives a camera 0.10-0.11 m
    high pitched 16-24 degrees down: self-consistent, a property of the mounting.
    """
    H = np.asarray(H, dtype=np.float64)
    if H.size != 9:
        raise _fail(where, f"homography has {H.size} values; expected 9 (row-major 3x3)")
    H = H.reshape(3, 3)
    if not np.all(np.isfinite(H)):
        raise _fail(where, "homography contains NaN or infinite values; recalibrate the extrinsics")
    sv = np.linalg.svd(H, compute_uv=False)
    if sv[0] == 0 or sv[-1] / sv[0] < 1e-14:
        raise _fail(where, "homography is singular (it maps the image onto a line or a point); "
                           "recalibrate the extrinsics")
    if not corrupt_rule:  # a robot whose camera sees its ground this way (the DD24: dtscal_lib.profiles)
        pass
    elif dt.homography_is_corrupt(H) and not writing:
        _warn(where, f"homography has H[1][2] = {H[1, 2]:g} > 0: the camera's image is rotated 180 degrees "
                     "(mounted upside-down), or the corners were mirrored or mis-ordered. Duckietown reads such "
                     "files but its calibration refuses to write them; check the robot's ground projection")
    elif dt.homography_is_corrupt(H):
        raise _fail(where, f"homography has H[1][2] = {H[1, 2]:g} > 0, which Duckietown rejects as corrupt: "
                           "with H[2][2] = 1, (H[0][2], H[1][2]) is where the image's top-left pixel lands "
                           "on the ground; that pixel is above the horizon and lands behind the robot on its "
                           "right (y < 0) when the board was seen the right way round. A positive value "
                           "usually means mirrored or mis-ordered corners: place the board as instructed "
                           "and recalibrate")
    return H


def load_extrinsics(path) -> np.ndarray:
    """Read and validate a ``camera_extrinsic/<ROBOT>.yaml``.

    Returns
    -------
    (3, 3) float64 homography, rectified pixels -> ground metres (x forward, y left).
    """
    doc, where = _read_yaml(path)
    if "homography" not in doc:
        raise _fail(where, "missing field 'homography' (expected homography: [9 numbers, row-major])")
    data = doc["homography"]
    if not isinstance(data, list):
        raise _fail(where, f"homography must be a list of 9 numbers, got {type(data).__name__}")
    if len(data) != 9:
        raise _fail(where, f"homography has {len(data)} values; expected 9 (row-major 3x3)")
    vals = [_number(v, where, f"homography[{i}]") for i, v in enumerate(data)]
    return validate_homography(vals, where)


# --------------------------------------------------------------------------- writing
def _dump(doc: dict) -> str:
    # default_flow_style=None: lists of numbers in [..], mappings as blocks, like the robot's files
    return yaml.safe_dump(doc, default_flow_style=None, sort_keys=False, width=4096)


#: a temporary file of the kit older than this (seconds) belongs to a killed writer
STALE_TMP_SECONDS = 300


def _remove_stale_temporaries(path: Path) -> None:
    """Remove temporary files a killed writer of ``path`` left (``.NAME[.bak].XXXXXXXX.tmp``)."""
    pattern = re.compile(r"\." + re.escape(path.name) + r"(\.bak)?\.[a-z0-9_]{8}\.tmp")
    now = time.time()
    try:
        entries = list(os.scandir(path.parent))
    except OSError:
        return
    for e in entries:
        if pattern.fullmatch(e.name):
            try:
                old = now - e.stat(follow_symlinks=False).st_mtime > STALE_TMP_SECONDS
                if old and e.is_file(follow_symlinks=False):
                    os.unlink(e.path)
            except OSError:
                pass


def _atomic_write(path: Path, text: str, *, backup: bool = True) -> Path:
    """Write ``text`` to ``path`` by the kit's one rule (:func:`.safe_write.output`: atomic, the
    previous file's mode kept, a new one by the umask, a device written through, never replaced);
    keep the previous file as ``path.bak``. Stale temporary files of earlier, killed writes are removed.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    _remove_stale_temporaries(path)
    try:
        with safe_write.output(path, what="calibration file", fsync=False) as tmp:
            with open(tmp, "w", encoding="utf-8") as f:  # on disk before the backup is touched
                f.write(text)
                f.flush()
                os.fsync(f.fileno())
            if backup and path.is_file():
                bak = path.with_name(path.name + ".bak")
                with safe_write.output(bak, what="backup of the calibration file", fsync=False) as tmp_bak:
                    shutil.copy2(path, tmp_bak)
    except DtscalError as exc:  # a target that is no file (a folder where the .bak goes): refused
        raise CalibrationFileError(f"{path}: could not be written ({exc}); the previous file is "
                                   "unchanged") from None
    _fsync_dir(path.parent)
    return path


def _fsync_dir(d: Path) -> None:
    try:
        fd = os.open(d, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _write(path: Path, doc: dict, backup: bool = True) -> Path:
    try:
        text = _dump(doc)
        return _atomic_write(path, text, backup=backup)
    except OSError as e:
        raise CalibrationFileError(f"{path}: could not be written ({e}); the previous file is unchanged. "
                                   "Check that the folder exists and is writable") from e


def _target(path: Path, rejected: bool) -> Path:
    """``NAME.yaml``, or ``NAME.rejected.yaml`` beside it for a calibration kept against the kit's doubts."""
    return path.with_name(path.stem + REJECTED_SUFFIX + path.suffix) if rejected else path


def save_intrinsics(calib: IntrinsicCalibration, out_dir, robot: str, *, rejected: bool = False,
                    uncertainty=None) -> Path:
    """Write ``out_dir/camera_intrinsic/<robot>.yaml`` atomically (previous one kept as ``.bak``).

    Refuses ``robot == "default"``: the factory file is never overwritten. ``rejected``
    writes ``<robot>.rejected.yaml`` instead, leaving ``<robot>.yaml`` alone. ``uncertainty`` (a
    :class:`~dtscal_lib.file_uncertainty.FileUncertainty` of this calibration) is appended as the extra key
    ``dtscal_uncertainty``, which ROS's and Duckietown's readers ignore; without it the file is exactly ROS's.
    """
    check_robot_name(robot)
    if not isinstance(calib, IntrinsicCalibration):
        raise CalibrationFileError(f"save_intrinsics needs an IntrinsicCalibration, got {type(calib).__name__}")
    doc = calib.to_dict()
    if uncertainty is not None:
        from .file_uncertainty import KEY

        off = uncertainty.mismatch(calib)
        if off:
            raise CalibrationFileError(f"the uncertainty given does not belong to this calibration: {off}")
        doc[KEY] = uncertainty.to_dict()
    return _write(_target(intrinsic_path(out_dir, robot), rejected), doc)


def save_extrinsics(H, out_dir, robot: str, *, rejected: bool = False, corrupt_rule: bool = True) -> Path:
    """Write ``out_dir/camera_extrinsic/<robot>.yaml`` (``homography: [9 floats]``) atomically.

    ``H`` (3, 3) maps rectified pixels to ground metres; it is validated (finite,
    non-singular, not corrupt) before anything is written. Refuses ``robot == "default"``.
    ``rejected`` writes ``<robot>.rejected.yaml`` instead, leaving ``<robot>.yaml`` alone.
    """
    check_robot_name(robot)
    path = _target(extrinsic_path(out_dir, robot), rejected)
    H = validate_homography(H, f"{path} (not written)", writing=True, corrupt_rule=corrupt_rule)
    return _write(path, {"homography": [_plain(v) for v in H.ravel()]})


def write_defaults(out_dir) -> list[Path]:
    """Create the factory ``default.yaml`` files under ``out_dir`` where they are missing.

    Writes ``camera_intrinsic/default.yaml`` and ``camera_extrinsic/default.yaml`` with
    the values of :mod:`dtscal_lib.duckietown`; an existing ``default.yaml`` is never
    touched.

    Returns
    -------
    list of Path
        The files written (empty when both already existed).
    """
    written = []
    ip = intrinsic_path(out_dir, dt.DEFAULT_NAME)
    if not ip.exists():
        doc = IntrinsicCalibration.from_dict(dt.DEFAULT_INTRINSICS, "duckietown.DEFAULT_INTRINSICS").to_dict()
        written.append(_write(ip, doc, backup=False))
    ep = extrinsic_path(out_dir, dt.DEFAULT_NAME)
    if not ep.exists():
        validate_homography(dt.DEFAULT_HOMOGRAPHY, "duckietown.DEFAULT_HOMOGRAPHY")
        written.append(_write(ep, {"homography": list(dt.DEFAULT_HOMOGRAPHY)}, backup=False))
    return written


# --------------------------------------------------------------------------- extrinsic file formats
#: the comment header Duckietown's current library (lib-dt-computer-vision) writes above a version-2 file
V2_HEADER = ("# IMPORTANT: Do not use this homography directly with your images. The homography in this file is\n"
             "#            stored in a resolution-independent format (version 2, written by dtscal).\n")


def _v2_frame(calib: IntrinsicCalibration) -> tuple[np.ndarray, np.ndarray]:
    """``(Kp, Hv2i)`` of the rectified camera ``P``: pixel->vector and vector->[0, 1] image coordinates."""
    Kp = np.array(calib.P[:, :3], dtype=np.float64)
    fx, fy, cx, cy = Kp[0, 0], Kp[1, 1], Kp[0, 2], Kp[1, 2]
    tl = np.array([-cx / fx, -cy / fy])
    br = np.array([(calib.width - 1 - cx) / fx, (calib.height - 1 - cy) / fy])
    sx, sy = 1.0 / (br - tl)
    return Kp, np.array([[sx, 0, -tl[0] * sx], [0, sy, -tl[1] * sy], [0, 0, 1.0]])


def extrinsic_to_v2(H, calib: IntrinsicCalibration, corrupt_rule: bool = True) -> np.ndarray:
    """Classic homography (rectified pixel -> ground m) -> the 3x3 matrix of a version-2 file.

    Mirrors lib-dt-computer-vision: its tool fits ``H_v`` from normalized image vectors
    ``Kp^-1 [u, v, 1]`` of the rectified image to the ground and stores ``inv(Hv2i) @ H_v``
    (``ResolutionDependentHomography.camera_independent``); its reader undoes exactly that
    (``camera_specific``: ``Hv2i @ F``). ``Kp`` is the rectified camera (``P[:, :3]``).
    """
    Kp, Hv2i = _v2_frame(calib)
    Hv = validate_homography(H, "classic homography", writing=True, corrupt_rule=corrupt_rule) @ Kp
    return np.linalg.inv(Hv2i) @ (Hv / Hv[2, 2])


#: how a version-2 matrix is read: ``"independent"`` (Duckietown's current format, ``camera_specific``) or
#: ``"vector"`` (the matrix maps the camera's normalized image vectors to the ground, as Duckietown's DD24
#: reference ``assets/extrinsics/dd24/real-world/scenario0/homography.yaml`` stores it: see :func:`v2_reading`)
V2_READINGS = ("independent", "vector")


def extrinsic_from_v2(F, calib: IntrinsicCalibration, where: str = "version-2 homography",
                      reading: str = "independent") -> np.ndarray:
    """The 3x3 matrix of a version-2 file -> classic homography (rectified pixel -> ground m), ``H[2,2] = 1``.

    ``reading="vector"``: ``F`` maps normalized image vectors ``pixel2vector(p) = K^-1 p`` of ``calib``'s
    camera (lib-dt-computer-vision's ``CameraModel.pixel2vector`` uses ``K``) to the ground, so ``H = F K^-1``.
    """
    F = np.asarray(F, dtype=np.float64)
    if F.size != 9 or not np.all(np.isfinite(F)):
        raise _fail(where, "a version-2 homography is 3 rows of 3 finite numbers")
    if reading not in V2_READINGS:
        raise _fail(where, f"unknown version-2 reading {reading!r}; use one of {', '.join(V2_READINGS)}")
    Kp, Hv2i = _v2_frame(calib)
    if reading == "vector":
        H = F.reshape(3, 3) @ np.linalg.inv(np.array(calib.K, dtype=np.float64))
    else:
        H = (Hv2i @ F.reshape(3, 3)) @ np.linalg.inv(Kp)
    if abs(H[2, 2]) < 1e-12:
        raise _fail(where, "maps the image to points at infinity; recalibrate the extrinsics")
    return validate_homography(H / H[2, 2], where)


def v2_reading(doc: dict, text: str, where: str) -> str:
    """Which matrix a version-2 file holds (see ``docs/robot.md``, "Duckietown's second robot").

    * ``format: resolution-independent``: Duckietown's current writer (lib-dt-computer-vision
      ``camera/homography.py``, ``HomographyToolkit.save_to_disk``), read with ``camera_specific``.
    * no ``format`` key, written by dtscal (its header says so): the kit's own files before it wrote the key,
      the same matrix.
    * no ``format`` key otherwise: an older Duckietown file. Its DD24 reference (``scenario0/homography.yaml``,
      2024-08-18) was written by ``notebooks/22-extrinsics-calibration-dd24.ipynb`` straight from
      ``estimate_homography``: normalized image vectors of the 240x320 camera -> ground (the notebook prints the
      same nine numbers). Duckietown's current ``load_from_disk`` refuses such a file (no ``format``).
    """
    fmt = doc.get("format")
    if fmt is not None:
        if str(fmt).strip().lower() != "resolution-independent":
            raise _fail(where, f"version-2 format {fmt!r} is not supported (resolution-independent)")
        return "independent"
    return "independent" if "written by dtscal" in text else "vector"


def read_extrinsic_file(path, intrinsics=None, reading: str | None = None) -> tuple[np.ndarray, str, str | None]:
    """Read a classic or version-2 ``camera_extrinsic`` file as ``(H, format, date)``.

    ``H`` is always the classic homography (rectified pixel -> ground metres); ``format`` is
    ``"classic"`` or ``"2"``; ``date`` the file's ISO date (None for classic). A version-2 file
    needs ``intrinsics`` (an :class:`IntrinsicCalibration` or the path of one) to be converted;
    ``reading`` (one of :data:`V2_READINGS`) overrides what :func:`v2_reading` infers from the file.
    """
    doc, where = _read_yaml(path)
    if "version" not in doc:
        return load_extrinsics(path), "classic", None
    if str(doc["version"]).strip() != "2":
        raise _fail(where, f"extrinsic file version {doc['version']!r} is not supported (classic or '2')")
    rows = doc.get("homography")
    if isinstance(rows, list) and len(rows) == 9 and not any(isinstance(r, (list, dict)) for r in rows):
        rows = [rows[0:3], rows[3:6], rows[6:9]]  # 9 numbers in a row: Duckietown's reader reshapes them (3, 3)
    if not (isinstance(rows, list) and len(rows) == 3 and all(isinstance(r, list) and len(r) == 3 for r in rows)):
        raise _fail(where, "a version-2 file needs homography: as 3 rows of 3 numbers (or 9 numbers)")
    F = [[_number(v, where, f"homography[{i}][{j}]") for j, v in enumerate(r)] for i, r in enumerate(rows)]
    if intrinsics is None:
        raise _fail(where, "is a version-2 (resolution-independent) file; pass the robot's intrinsic file "
                           "to convert it (--intrinsics camera_intrinsic/ROBOT.yaml)")
    calib = intrinsics if isinstance(intrinsics, IntrinsicCalibration) else load_intrinsics(intrinsics)
    date = doc.get("date")
    if reading is None:
        reading = v2_reading(doc, Path(path).read_text(encoding="utf-8", errors="replace"), where)
    return extrinsic_from_v2(F, calib, where, reading), "2", None if date is None else str(date)


def save_extrinsics_as(H, out_dir, robot: str, *, fmt: str = "classic", intrinsics=None, date=None,
                       rejected: bool = False, corrupt_rule: bool = True) -> Path:
    """Write ``camera_extrinsic/<robot>.yaml`` in the classic format (default) or as version ``"2"``.

    ``H`` is the classic homography; ``fmt="2"`` needs ``intrinsics`` (object or path) and stamps
    ``date`` (default now, ISO 8601). ``rejected`` writes ``<robot>.rejected.yaml`` beside, in either format.
    """
    if fmt == "classic":
        return save_extrinsics(H, out_dir, robot, rejected=rejected, corrupt_rule=corrupt_rule)
    if fmt != "2":
        raise CalibrationFileError(f"extrinsic format {fmt!r} is unknown; use 'classic' or '2'")
    if intrinsics is None:
        raise CalibrationFileError("the version-2 extrinsic format needs the intrinsic calibration; pass intrinsics=")
    import datetime

    calib = intrinsics if isinstance(intrinsics, IntrinsicCalibration) else load_intrinsics(intrinsics)
    check_robot_name(robot)
    path = _target(extrinsic_path(out_dir, robot), rejected)
    F = extrinsic_to_v2(H, calib, corrupt_rule)
    stamp = (date or datetime.datetime.now()).isoformat() if not isinstance(date, str) else date
    # "format" as Duckietown's save_to_disk writes it: its load_from_disk refuses a version-2 file without it
    text = V2_HEADER + "\n" + _dump({"version": "2", "format": "resolution-independent", "date": stamp,
                                     "homography": [[float(v) for v in r] for r in F]})
    try:
        return _atomic_write(path, text)
    except OSError as e:
        raise CalibrationFileError(f"{path}: could not be written ({e}); the previous file is unchanged. "
                                   "Check that the folder exists and is writable") from e
