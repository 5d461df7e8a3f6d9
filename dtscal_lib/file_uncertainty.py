"""σ travels with the file: a calibration's uncertainty stored beside its ROS fields, for ``dtscal compare``.

The kit writes ``camera_intrinsic/ROBOT.yaml`` in ROS's ``CameraInfo`` layout (:mod:`dtscal_lib.calib_files`)
and appends one extra key, ``dtscal_uncertainty``, holding what is needed to propagate the calibration's
uncertainty to the projection of directions (points at infinity, mrcal's default for ``projection_diff``):

* ``parameters``: the estimated intrinsics in the solver's order (``fx, fy, cx, cy, [skew], k1, k2, [p1, p2,
  [k3]]``; the file's other coefficients were held at 0) and ``rx, ry, rz``, a small rotation of the camera's
  rays (``v -> v + r x v``);
* ``covariance``: their joint covariance, ``{rows, cols, data}`` like ROS's matrices. The intrinsics' block is
  the calibration's honest covariance (``CalibrationResult.intrinsic_covariance``: the larger of the corner-noise
  model and the views' disagreement, :mod:`dtscal_lib.covariance`); the rotation carries what the boards' poses
  add at infinity (:func:`dtscal_lib.covariance.ray_rotation_covariance`), so the projection uncertainty computed
  from the file equals the one computed from the calibration with its views;
* ``at``: the intrinsics' values the covariance belongs to (a file edited afterwards no longer matches; its σ
  is then ignored, and ``compare`` says so); ``noise_sigma_px``, ``views``, ``model``, ``method``: provenance.

Why an extra key and no sidecar: every reader of the file reads its fields by name and ignores the rest. ROS's
``camera_calibration_parsers`` (``parse_yml.cpp``, ``readCalibrationYml``: ``doc["camera_matrix"]``, ... with
yaml-cpp), Duckietown's camera node (``dt-duckiebot-interface``, ``camera_driver/src/camera_node.py``,
``load_camera_info``: ``calib_data['camera_matrix']['data']``, ...) and the kit's own reader
(:meth:`~dtscal_lib.calib_files.IntrinsicCalibration.from_dict`). What the kit sends to a robot is rebuilt from
the named fields (``robot.commit_*``), so the robot's copy carries no σ, and a robot that rewrites the file
(``set_camera_info``, ``save_camera_info``) drops the key rather than leaving a stale σ beside new values, which a
sidecar file would.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import DtscalError

__all__ = ["KEY", "ROTATION", "FileUncertainty", "from_result", "from_document", "file_values"]

#: the extra key of the intrinsic file
KEY = "dtscal_uncertainty"
#: the names of the rays' rotation in ``parameters``
ROTATION = ("rx", "ry", "rz")
#: what the block says about itself, written into the file
ABOUT = ("joint covariance of the estimated intrinsics and of a small rotation of the camera's rays "
         "(v -> v + r x v), for the projection uncertainty of directions; read by dtscal compare, ignored by ROS "
         "and Duckietown")
#: the file's values must equal ``at`` to this relative precision (the file's floats are written by repr: equal)
_AT_REL = 1e-9
_DIST = ("k1", "k2", "p1", "p2", "k3")


def file_values(camera, names) -> np.ndarray:
    """The values of the named intrinsics (``fx fy cx cy skew k1 k2 p1 p2 k3``) of a camera or file."""
    K, d = np.asarray(camera.K, dtype=np.float64), np.asarray(camera.dist, dtype=np.float64).ravel()
    table = {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2], "skew": K[0, 1]}
    table.update({n: (d[i] if i < len(d) else 0.0) for i, n in enumerate(_DIST)})
    return np.array([table[n] for n in names], dtype=np.float64)


@dataclass(frozen=True)
class FileUncertainty:
    """The block ``dtscal_uncertainty`` of an intrinsic file (module docstring)."""

    names: tuple
    covariance: np.ndarray
    at: np.ndarray
    noise_sigma_px: float
    n_views: int
    model: str
    method: str

    @property
    def intrinsics(self) -> tuple:
        return tuple(self.names[:-3])

    def mismatch(self, camera) -> str | None:
        """Why this σ does not belong to ``camera`` (its values differ from ``at``), or None."""
        if str(getattr(camera, "model", "")) not in ("plumb_bob", "radial2"):
            return f"its lens model {getattr(camera, 'model', '?')} is not the kit solver's (plumb_bob)"
        have = file_values(camera, self.intrinsics)
        off = np.abs(have - self.at) > _AT_REL * np.maximum(np.abs(self.at), 1.0)
        if off.any():
            i = int(np.flatnonzero(off)[0])
            return (f"its {self.names[i]} is {have[i]:.6g} where the uncertainty was computed at {self.at[i]:.6g}: "
                    "the file was edited after calibration")
        return None

    def projection_sigma(self, camera, pixels) -> np.ndarray:
        """Worst-direction 1-sigma (M,) of the projection of the directions seen at ``pixels`` under ``camera``
        (the covariance propagated through ``J = [dq/dI, -dq/dP [v]_x]``, :func:`ray_rotation_covariance`)."""
        from .covariance import _skew_matrices
        from .uncertainty import _projection_jacobian, _rays, worst_direction_sigma

        pix = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        rays = _rays(camera, pix)
        idx = [_DIST.index(n) for n in self.intrinsics if n in _DIST]
        dist5 = np.zeros(5)
        d = np.asarray(camera.dist, dtype=np.float64).ravel()
        dist5[:min(5, len(d))] = d[:5]
        with np.errstate(invalid="ignore"):  # NaN rays (a model that cannot be inverted there) stay NaN
            _, dqdP, dqdI = _projection_jacobian(rays, np.asarray(camera.K, dtype=np.float64), dist5,
                                                 "skew" in self.names, idx)
            J = np.concatenate([dqdI, -dqdP @ _skew_matrices(rays)], axis=2)
            return worst_direction_sigma(J @ self.covariance @ J.transpose(0, 2, 1))

    def to_dict(self) -> dict:
        """The block as written (floats by ``repr``, so they read back exactly; nothing called back in
        :mod:`~dtscal_lib.calib_files`, which writes it)."""
        n = len(self.names)
        return {"about": ABOUT, "parameters": list(self.names), "at": [float(v) for v in self.at],
                "covariance": {"rows": n, "cols": n, "data": [float(v) for v in self.covariance.ravel()]},
                "noise_sigma_px": float(self.noise_sigma_px), "views": int(self.n_views), "model": self.model,
                "method": self.method}

    def describe(self) -> str:
        return f"{self.n_views} views, noise {self.noise_sigma_px:.3f} px"


def from_result(result) -> FileUncertainty | None:
    """The block for a calibration result of the kit's solver that carries its views; None for OpenCV's models
    (no covariance) or a result without views."""
    from .camera import KIT_SOLVER_MODELS
    from .covariance import ray_rotation_covariance
    from .uncertainty import pose_omegas

    if result is None or result.model not in KIT_SOLVER_MODELS or not getattr(result, "object_points", None):
        return None
    cov = ray_rotation_covariance(result.normal_blocks(), result.intrinsic_covariance(), pose_omegas(result.rvecs))
    names = tuple(result.std) + ROTATION
    if not np.all(np.isfinite(cov)) or len(names) != len(cov):
        return None
    return FileUncertainty(names, cov, file_values(result, names[:-3]), float(result.sigma), int(result.n_views),
                           str(result.model), str(result.std_method))


def from_document(doc: dict, where: str) -> tuple[FileUncertainty | None, str]:
    """The block of a parsed intrinsic file, or None and the sentence saying why there is none."""
    block = doc.get(KEY) if isinstance(doc, dict) else None
    if block is None:
        return None, (f"{where} carries no uncertainty ({KEY}: the kit writes it for its own solver's models; "
                      "a file from ROS or Duckietown has none)")
    bad = f"{where}: its {KEY} block is malformed"
    try:
        names = tuple(str(n) for n in block["parameters"])
        cov = block["covariance"]
        n = len(names)
        C = np.array(cov["data"], dtype=np.float64)
        at = np.array(block["at"], dtype=np.float64)
        known = {"fx", "fy", "cx", "cy", "skew", *_DIST}
        if (names[-3:] != ROTATION or not set(names[:-3]) <= known or names[:4] != ("fx", "fy", "cx", "cy")
                or cov["rows"] != n or cov["cols"] != n or C.size != n * n or at.size != n - 3):
            return None, f"{bad} (parameters, at and covariance do not fit together); it is ignored"
        C = C.reshape(n, n)
        if not (np.all(np.isfinite(C)) and np.all(np.isfinite(at))):
            return None, f"{bad} (NaN or infinite values); it is ignored"
        scale = np.sqrt(np.abs(np.diag(C)))
        if np.abs(C - C.T).max() > 1e-9 * max(float(np.outer(scale, scale).max()), 1e-300) \
                or np.linalg.eigvalsh(C / np.outer(scale, scale).clip(1e-300)).min() < -1e-9 or np.any(scale == 0):
            return None, f"{bad} (the covariance is not symmetric positive definite); it is ignored"
        unc = FileUncertainty(names, C, at, float(block.get("noise_sigma_px", float("nan"))),
                              int(block.get("views", 0)), str(block.get("model", "")), str(block.get("method", "")))
    except (KeyError, TypeError, ValueError, AttributeError, np.linalg.LinAlgError):
        return None, f"{bad}; it is ignored"
    return unc, ""


def load(path, camera=None) -> tuple[FileUncertainty | None, str]:
    """The σ block of the intrinsic file ``path`` (checked against ``camera``, the file's content, when given),
    or None and the sentence saying why not."""
    from .calib_files import _read_yaml, load_intrinsics

    try:
        doc, where = _read_yaml(path)
        camera = load_intrinsics(path) if camera is None else camera
    except DtscalError as exc:
        return None, str(exc)
    unc, why = from_document(doc, where)
    if unc is None:
        return None, why
    off = unc.mismatch(camera)
    if off:
        return None, f"{where}'s uncertainty is ignored: {off}"
    return unc, ""
