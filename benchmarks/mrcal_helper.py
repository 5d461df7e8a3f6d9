"""mrcal side of ``benchmarks/bench_mrcal.py``: run on Debian's ``/usr/bin/python3`` (``python3-mrcal``).

mrcal 2.2 is packaged for Debian's Python, not for the project's venv, so the benchmark starts this
script as a separate process (``scripts/install-mrcal.sh`` installs it) and exchanges JSON: the
request on stdin, the answer on stdout. Only the standard library, numpy and mrcal are used.

Request::

    {"image_size": [W, H], "spacing": 0.03, "lensmodel": "LENSMODEL_OPENCV5", "focal_estimate": 640,
     "corners": [V][rows][cols][2] pixels (mrcal's layout: board point (col*spacing, row*spacing, 0)),
     "pixels": [M][2], "distance": 0.4, "regularization": false}

Answer::

    {"mrcal_version": ..., "lensmodel": ..., "intrinsics": [fx, fy, cx, cy, k1, k2, p1, p2, k3],
     "intrinsics_std": [...] (1 sigma, from mrcal's covariance of the solution),
     "sigma": observed pixel noise (std of the board residuals, per coordinate, as mrcal infers it),
     "rms": sqrt(sum over points |residual|^2 / N), "rms_reproj_error__pixels": mrcal's own figure,
     "projection_cov": [M][2][2] mrcal.projection_uncertainty(what="covariance") at ``distance``,
     "n_outliers": ...,
     "warp": {"calobject_warp": [x, y] (object unit), "rms": ...} when "warp": true was asked (the board's
         two-parameter warp fitted last, on a copy: every other figure is of the flat board), else null}

The fit: seeded by ``mrcal.seed_stereographic`` (from ``focal_estimate``, not from the kit's
answer), then solved as ``mrcal-calibrate-cameras`` does, the lens core first and then everything,
with ``do_apply_outlier_rejection=False`` (every corner the kit used) and, unless
``regularization`` is true, ``do_apply_regularization=False`` (the kit's cost function exactly).
"""

import json
import sys

import numpy as np


def _fail(message):
    json.dump({"error": message}, sys.stdout)
    sys.stdout.write("\n")
    sys.exit(2)


def main():
    try:
        import mrcal
        from mrcal import model_analysis
    except ImportError as exc:
        _fail(f"cannot import mrcal on {sys.executable}: {exc} (run scripts/install-mrcal.sh)")
    req = json.load(sys.stdin)
    W, H = (int(v) for v in req["image_size"])
    spacing = float(req["spacing"])
    lensmodel = req.get("lensmodel", "LENSMODEL_OPENCV5")
    regularization = bool(req.get("regularization", False))
    corners = np.asarray(req["corners"], dtype=float)  # (V, rows, cols, 2)
    V = corners.shape[0]
    obs = np.concatenate([corners, np.ones(corners.shape[:-1] + (1,))], axis=-1)  # weight 1 everywhere
    imagersizes = np.array([[W, H]], dtype=np.int32)

    core, _, frames = mrcal.seed_stereographic(
        imagersizes=imagersizes, focal_estimate=float(req.get("focal_estimate", W)),
        indices_frame_camera=np.array([[i, 0] for i in range(V)], dtype=np.int32),
        observations=obs, object_spacing=spacing)
    n_dist = mrcal.lensmodel_num_params(lensmodel) - 4
    intrinsics = np.concatenate([core[:, :4], np.zeros((1, n_dist))], axis=1)

    oi = dict(intrinsics=intrinsics,
              extrinsics_rt_fromref=np.zeros((0, 6)),
              frames_rt_toref=frames,
              points=None,
              observations_board=obs,
              indices_frame_camintrinsics_camextrinsics=np.array([[i, 0, -1] for i in range(V)], dtype=np.int32),
              observations_point=None,
              indices_point_camintrinsics_camextrinsics=None,
              lensmodel=lensmodel,
              imagersizes=imagersizes,
              calibration_object_spacing=spacing,
              do_optimize_intrinsics_core=True,
              do_optimize_intrinsics_distortions=False,
              do_optimize_extrinsics=True,  # there are none (one camera at the reference); mrcal needs it set
              do_optimize_frames=True,
              do_optimize_calobject_warp=False,
              do_apply_outlier_rejection=False,
              do_apply_regularization=regularization)
    mrcal.optimize(**oi)  # the core with no distortion, as mrcal-calibrate-cameras seeds
    oi["do_optimize_intrinsics_distortions"] = True
    stats = mrcal.optimize(**oi)

    # the covariance of the solution, exactly as mrcal.projection_uncertainty propagates it
    b, x, J, factorization = mrcal.optimizer_callback(**oi)
    sigma = float(np.std(mrcal.residuals_chessboard(oi, residuals=x).ravel()))
    n_obs = mrcal.num_measurements_boards(**oi)
    if n_obs == mrcal.num_measurements(**oi):
        n_obs = None
    n_int = mrcal.lensmodel_num_params(lensmodel)
    i0 = mrcal.state_index_intrinsics(0, **oi)
    dF_db = np.zeros((n_int, J.shape[1]))
    dF_db[np.arange(n_int), i0 + np.arange(n_int)] = 1.0
    mrcal.unpack_state(dF_db, **oi)  # the state is in the denominator (as model_analysis does)
    cov_int = model_analysis._propagate_calibration_uncertainty(dF_db, factorization, J, n_obs, sigma,
                                                                 "covariance")

    model = mrcal.cameramodel(optimization_inputs=oi, icam_intrinsics=0)
    pix = np.asarray(req.get("pixels", []), dtype=float).reshape(-1, 2)
    pcov = []
    if len(pix):
        p_cam = float(req["distance"]) * mrcal.unproject(pix, lensmodel, oi["intrinsics"][0], normalize=True)
        pcov = mrcal.projection_uncertainty(p_cam, model, what="covariance",
                                            observed_pixel_uncertainty=sigma).tolist()

    res = mrcal.residuals_chessboard(oi, residuals=x)
    warp = None
    if req.get("warp"):  # then the board's warp too, as mrcal-calibrate-cameras does last (on a copy)
        ow = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in oi.items()}
        ow["calobject_warp"] = np.zeros(2)
        ow["do_optimize_calobject_warp"] = True
        sw = mrcal.optimize(**ow)
        warp = {"calobject_warp": ow["calobject_warp"].tolist(), "rms": float(sw["rms_reproj_error__pixels"])}
    json.dump({
        "mrcal_version": getattr(mrcal, "__version__", "2.2 (Debian python3-mrcal)"),
        "python": sys.executable,
        "lensmodel": lensmodel,
        "regularization": regularization,
        "intrinsics": oi["intrinsics"][0].tolist(),
        "intrinsics_std": np.sqrt(np.diag(cov_int)).tolist(),
        "sigma": sigma,
        "rms": float(np.sqrt((res ** 2).sum() / len(res))),
        "rms_reproj_error__pixels": float(stats["rms_reproj_error__pixels"]),
        "n_outliers": int(stats.get("Noutliers", 0)),
        "n_views": V,
        "warp": warp,
        "projection_cov": pcov,
    }, sys.stdout)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
