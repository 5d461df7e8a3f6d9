"""mrcal side of ``benchmarks/bench_compare.py``: ``mrcal.projection_diff`` on two models, on Debian's Python.

Request (JSON on stdin)::

    {"models": [{"lensmodel": "LENSMODEL_OPENCV5", "intrinsics": [fx, fy, cx, cy, k1, ...],
                 "imagersize": [W, H]}, {...}], "gridn_width": 60}

Answer: ``{"difflen": [[...]] (gridn_height x gridn_width, pixels), "q0": [...], "Rt10": [[...]]}``, from
``mrcal.projection_diff(models, gridn_width=..., use_uncertainties=False)`` (the models carry no
optimization inputs, so mrcal fits the rotation over its default focus region, min(W, H)/6 around the centre,
at infinity).

With ``"sigma": {"parameters": [...], "covariance": [[...]]}`` in both models (a kit file's
``dtscal_uncertainty``: intrinsics by name, then ``rx, ry, rz``, a rotation of the rays ``v -> v + r x v``),
the files' sigma is propagated here with mrcal's own gradients (``mrcal.project(..., get_gradients=True)``:
``J = [dq/dintrinsics, -dq/dv [v]_x]``, worst direction of ``J C J^T`` at each model's unprojected grid), and
the difference is mrcal's ``projection_diff`` with uncertainties, step by step as mrcal 2.2 writes it
(``model_analysis.py``), these sigmas in place of ``mrcal.projection_uncertainty``: weights
``(1 / (sigma_0 sigma_1))^2`` over the whole imager, ``mrcal.implied_Rt10__from_unprojections`` at infinity,
``mrcal.project`` of the rotated rays. The answer then also holds ``"sigma": [[grid], [grid]]``.
"""

import json
import sys

import numpy as np


#: mrcal's LENSMODEL_OPENCV4/5 intrinsics, in order; the kit names its parameters alike
MRCAL_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


def _file_sigma(mrcal, model, sigma, v):
    """Worst-direction 1-sigma of the projection of the rays ``v`` (..., 3) from a file's covariance."""
    names, C = sigma["parameters"], np.asarray(sigma["covariance"], dtype=float)
    _, dq_dv, dq_di = mrcal.project(v, *model.intrinsics(), get_gradients=True)
    cols = [MRCAL_NAMES.index(n) for n in names[:-3]]
    vx = np.zeros(v.shape + (3,))
    vx[..., 0, 1], vx[..., 0, 2], vx[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    vx[..., 1, 0], vx[..., 2, 0], vx[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    J = np.concatenate([dq_di[..., cols], -dq_dv @ vx], axis=-1)
    cov = J @ C @ np.swapaxes(J, -1, -2)
    a, b, c = cov[..., 0, 0], cov[..., 0, 1], cov[..., 1, 1]
    return np.sqrt((a + c) / 2 + np.sqrt(((a - c) / 2) ** 2 + b ** 2))


def _diff_with_file_sigma(mrcal, models, req_models, gridn):
    W, H = models[0].imagersize()
    lensmodels = [m.intrinsics()[0] for m in models]
    data = [m.intrinsics()[1] for m in models]
    v, q0 = mrcal.sample_imager_unproject(gridn, None, W, H, lensmodels, data, normalize=True)
    sig = [_file_sigma(mrcal, models[i], req_models[i]["sigma"], v[i]) for i in range(2)]
    weights = 1.0 / (sig[0] * sig[1])
    weights *= weights
    Rt10 = mrcal.implied_Rt10__from_unprojections(q0, v[0], v[1], weights=weights, atinfinity=True,
                                                  focus_center=((W - 1.0) / 2.0, (H - 1.0) / 2.0),
                                                  focus_radius=max(W, H) * 100)
    q1 = mrcal.project(mrcal.transform_point_Rt(Rt10, v[0]), lensmodels[1], data[1])
    return np.linalg.norm(q1 - q0, axis=-1), q0, Rt10, sig


def main():
    try:
        import mrcal
    except ImportError as exc:
        json.dump({"error": f"cannot import mrcal on {sys.executable}: {exc} (run scripts/install-mrcal.sh)"},
                  sys.stdout)
        sys.exit(2)
    req = json.load(sys.stdin)
    models = [mrcal.cameramodel(intrinsics=(m["lensmodel"], np.asarray(m["intrinsics"], dtype=float)),
                                imagersize=np.asarray(m["imagersize"], dtype=np.int32)) for m in req["models"]]
    gridn = int(req.get("gridn_width", 60))
    extra = {}
    if all("sigma" in m for m in req["models"]):
        difflen, q0, Rt10, sig = _diff_with_file_sigma(mrcal, models, req["models"], gridn)
        extra["sigma"] = [np.where(np.isfinite(s), s, -1.0).tolist() for s in sig]
    else:
        difflen, _, q0, Rt10 = mrcal.projection_diff(models, gridn_width=gridn, use_uncertainties=False)
    json.dump({"difflen": np.where(np.isfinite(difflen), difflen, -1.0).tolist(), "q0": q0.tolist(),
               "Rt10": np.asarray(Rt10).tolist(), "mrcal": getattr(mrcal, "__version__", "2.2"), **extra},
              sys.stdout)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
