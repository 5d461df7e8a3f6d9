"""mrcal side of ``benchmarks/bench_cross_validate.py``: half-set calibrations and their difference against
their uncertainty, on Debian's Python (``python3-mrcal``, ``scripts/install-mrcal.sh``).

Request (JSON on stdin)::

    {"image_size": [W, H], "spacing": 0.03, "lensmodel": "LENSMODEL_OPENCV4", "focal_estimate": 640,
     "pairs": [[corners_A, corners_B], ...]}   # each: [V][rows][cols][2] pixels, mrcal's board layout

For each pair both halves are calibrated as ``mrcal_helper.py`` does (seeded by mrcal.seed_stereographic, the
core then everything, no outlier rejection, no regularization), then
``mrcal.projection_diff(models, gridn_width=60)`` (uncertainty-weighted rotation at infinity, mrcal's default)
and ``mrcal.projection_uncertainty(..., atinfinity=True, what="worstdirection-stdev")`` of each model at the
grid: answer ``{"ratios": [{"corners": [4], "inside": max over the central two thirds, "max_px": ...}]}``.
"""

import json
import sys

import numpy as np


def _solve(mrcal, corners, W, H, spacing, lensmodel, focal):
    corners = np.asarray(corners, dtype=float)
    V = corners.shape[0]
    obs = np.concatenate([corners, np.ones(corners.shape[:-1] + (1,))], axis=-1)
    imagersizes = np.array([[W, H]], dtype=np.int32)
    core, _, frames = mrcal.seed_stereographic(
        imagersizes=imagersizes, focal_estimate=focal,
        indices_frame_camera=np.array([[i, 0] for i in range(V)], dtype=np.int32),
        observations=obs, object_spacing=spacing)
    n_dist = mrcal.lensmodel_num_params(lensmodel) - 4
    oi = dict(intrinsics=np.concatenate([core[:, :4], np.zeros((1, n_dist))], axis=1),
              extrinsics_rt_fromref=np.zeros((0, 6)), frames_rt_toref=frames, points=None,
              observations_board=obs,
              indices_frame_camintrinsics_camextrinsics=np.array([[i, 0, -1] for i in range(V)], dtype=np.int32),
              observations_point=None, indices_point_camintrinsics_camextrinsics=None,
              lensmodel=lensmodel, imagersizes=imagersizes, calibration_object_spacing=spacing,
              do_optimize_intrinsics_core=True, do_optimize_intrinsics_distortions=False,
              do_optimize_extrinsics=True, do_optimize_frames=True, do_optimize_calobject_warp=False,
              do_apply_outlier_rejection=False, do_apply_regularization=False)
    mrcal.optimize(**oi)
    oi["do_optimize_intrinsics_distortions"] = True
    mrcal.optimize(**oi)
    return mrcal.cameramodel(optimization_inputs=oi, icam_intrinsics=0)


def main():
    try:
        import mrcal
    except ImportError as exc:
        json.dump({"error": f"cannot import mrcal on {sys.executable}: {exc} (run scripts/install-mrcal.sh)"},
                  sys.stdout)
        sys.exit(2)
    req = json.load(sys.stdin)
    W, H = (int(v) for v in req["image_size"])
    out = []
    for a, b in req["pairs"]:
        models = [_solve(mrcal, c, W, H, float(req["spacing"]), req["lensmodel"], float(req["focal_estimate"]))
                  for c in (a, b)]
        difflen, _, q0, _ = mrcal.projection_diff(models, gridn_width=60)
        sig = []
        for m in models:
            v = mrcal.unproject(q0, *m.intrinsics(), normalize=True)
            sig.append(mrcal.projection_uncertainty(v, m, atinfinity=True, what="worstdirection-stdev"))
        ratio = difflen / np.sqrt(sig[0] ** 2 + sig[1] ** 2)
        u, v = q0[..., 0], q0[..., 1]
        inside = (u >= W / 6) & (u <= W - 1 - W / 6) & (v >= H / 6) & (v <= H - 1 - H / 6)
        corners = [ratio[0, 0], ratio[0, -1], ratio[-1, 0], ratio[-1, -1]]
        out.append({"corners": [float(c) for c in corners], "inside": float(np.nanmax(ratio[inside])),
                    "max_px": float(np.nanmax(difflen))})
    json.dump({"ratios": out}, sys.stdout)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
