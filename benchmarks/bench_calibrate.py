"""Benchmark: intrinsic calibration of 40 samples, dtscal vs raw ``cv2.calibrateCamera``.

The input is what a full CALIBRATE press gives ROS's calibrator: 40 views of the 7x5
Duckietown board (31 mm squares) at realistic poses (0.25-0.8 m, tilts up to 40
degrees, spread over the image) through the default Duckiebot camera
(``camera_intrinsic/default.yaml``: fx 308, k1 -0.257), with 0.2 px Gaussian noise on
the corners. Both calibrate ``plumb_bob`` with k3 fixed at 0, as ROS does.

Baseline, measured in the same run: ``cv2.calibrateCamera(..., flags=CALIB_FIX_K3)``
(what ROS runs). Target for ``dtscal_lib.calibration.calibrate``: < 0.5 s median.

Run::

    .venv/bin/python benchmarks/bench_calibrate.py [--json] [--check] [--repeats N]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common import median_time, random_visible_pose  # noqa: E402

from dtscal_lib import duckietown as dt  # noqa: E402
from dtscal_lib.boards import DUCKIETOWN_BOARD  # noqa: E402

TARGET_S = 0.5
#: calibrate() and the verdict's richer-model test together, against cv2.calibrateCamera on the same samples (issue 21)
RICHER_MAX_RATIO = 0.2
N_SAMPLES = 40
NOISE_PX = 0.2


def make_views(seed: int = 1, n: int = N_SAMPLES, noise: float = NOISE_PX):
    """40 noisy views of the board through the default Duckiebot camera."""
    rng = np.random.default_rng(seed)
    K, dist = dt.default_K(), dt.default_dist()
    obj = DUCKIETOWN_BOARD.object_points()
    objs, imgs = [], []
    for _ in range(n):
        _, _, corners = random_visible_pose(rng, DUCKIETOWN_BOARD, K, dist, distance=(0.25, 0.8),
                                            max_tilt=0.7, margin=10)
        objs.append(obj.copy())
        imgs.append(corners + rng.normal(0.0, noise, corners.shape))
    return objs, imgs


def opencv_calibrate(objs, imgs, size):
    rms, K, d, _, _ = cv2.calibrateCamera([o.astype(np.float32) for o in objs],
                                          [i.astype(np.float32).reshape(-1, 1, 2) for i in imgs],
                                          size, None, None, flags=cv2.CALIB_FIX_K3)
    return float(rms), K, d.ravel()


def load_dtscal_calibrate():
    """``dtscal_lib.calibration.calibrate`` or None if that module is not there yet."""
    try:
        from dtscal_lib.calibration import calibrate
    except ImportError as e:  # reported, not hidden: the table says which one ran
        print(f"note: dtscal_lib.calibration not importable ({e}); timing OpenCV only", file=sys.stderr)
        return None
    return calibrate


def run(repeats: int) -> dict:
    objs, imgs = make_views()
    size = dt.IMAGE_SIZE
    K_true, d_true = dt.default_K(), dt.default_dist()
    out = {"n_samples": len(objs), "noise_px": NOISE_PX, "target_s": TARGET_S}
    t_cv = median_time(opencv_calibrate, objs, imgs, size, repeats=repeats, warmup=1)
    rms, K, d = opencv_calibrate(objs, imgs, size)
    out["opencv"] = {"median_s": t_cv, "rms_px": rms, "fx_err": float(K[0, 0] - K_true[0, 0]),
                     "cx_err": float(K[0, 2] - K_true[0, 2]), "k1_err": float(d[0] - d_true[0])}
    calibrate = load_dtscal_calibrate()
    if calibrate is not None:
        def ours():
            return calibrate(objs, imgs, size, model="plumb_bob", skew=False)
        t_ours = median_time(ours, repeats=repeats, warmup=1)
        res = ours()
        out["dtscal"] = {"median_s": t_ours, "rms_px": float(res.rms),
                         "fx_err": float(res.K[0, 0] - K_true[0, 0]), "cx_err": float(res.K[0, 2] - K_true[0, 2]),
                         "k1_err": float(res.dist[0] - d_true[0]), "ratio_to_opencv": t_ours / t_cv,
                         "meets_target": t_ours < TARGET_S}
        # the richer-model test of the verdict (dtscal_lib.richer: k3, OpenCV's rational, mrcal's board warp),
        # which the verdict runs only when the residual is above fit_ratio_doubtful x the corner noise: here
        # forced, to time the worst case (issue 21: CALIBRATE with it at most 0.2x cv2.calibrateCamera)
        from dtscal_lib import rules
        from dtscal_lib.result import evidence

        def richer():
            return rules._richer_fits(res)  # every candidate: the worst case (a finer lens model explains)
        t_richer = median_time(richer, repeats=repeats, warmup=1)
        out["richer"] = {"median_s": t_richer, "ratio_to_opencv": t_richer / t_cv,
                         "with_calibrate_ratio": (t_ours + t_richer) / t_cv,
                         "meets_target": (t_ours + t_richer) / t_cv <= RICHER_MAX_RATIO}
        # the whole verdict step of the session (issue 31: calibration including the verdict <= 0.2x OpenCV),
        # and where its time goes: the evidence (normal equations), the preparation (residuals, corner noise,
        # uncertainty map, consequences) and each rule
        t_ev = median_time(lambda: evidence(res), repeats=repeats, warmup=1)
        ev = evidence(res)
        t_prep = median_time(lambda: rules.prepare(res, ev), repeats=repeats, warmup=1)
        case = rules.prepare(res, ev)
        parts = {"evidence": t_ev, "prepare": t_prep}
        for name, rule in rules.RULES:
            def one(rule=rule):
                c = rules.Case(**{k: getattr(case, k) for k in ("result", "evidence", "obj", "img", "res", "noise",
                                                                  "n_noise", "umap", "cov", "cons", "counts",
                                                                  "help_region")})
                for n2, r2 in rules.RULES:
                    if n2 == name:
                        break
                    r2(c)
                t0 = time.perf_counter()
                rule(c)
                return time.perf_counter() - t0
            parts[f"rule {name}"] = float(np.median([one() for _ in range(max(1, repeats))]))
        t_verdict = sum(parts.values())
        out["verdict"] = {"median_s": t_verdict, "parts_s": parts,
                          "with_calibrate_ratio": (t_ours + t_verdict) / t_cv,
                          "meets_target": (t_ours + t_verdict) / t_cv <= RICHER_MAX_RATIO}
    return out


def print_report(r: dict) -> None:
    print(f"Calibration of {r['n_samples']} samples (7x5 board, Duckiebot lens, {r['noise_px']} px noise), "
          "plumb_bob with k3 fixed; baseline: cv2.calibrateCamera (ROS's call) in the same run")
    print(f"{'':24s} {'median time':>12s} {'time/OpenCV':>11s} {'rms px':>8s} {'fx err':>8s} {'cx err':>8s} "
          f"{'k1 err':>9s}")
    rows = [("cv2.calibrateCamera", r["opencv"], 1.0)]
    if "dtscal" in r:
        rows.insert(0, ("dtscal calibrate()", r["dtscal"], r["dtscal"]["ratio_to_opencv"]))
    for name, v, ratio in rows:
        print(f"{name:24s} {v['median_s'] * 1e3:9.1f} ms {ratio:10.2f}x {v['rms_px']:8.3f} {v['fx_err']:8.3f} "
              f"{v['cx_err']:8.3f} {v['k1_err']:9.5f}")
    if "richer" in r:
        v = r["richer"]
        print(f"{'richer-model test':24s} {v['median_s'] * 1e3:9.1f} ms {v['ratio_to_opencv']:10.2f}x   "
              f"(calibrate + it: {v['with_calibrate_ratio']:.2f}x OpenCV, target <= {RICHER_MAX_RATIO}x: "
              f"{'ok' if v['meets_target'] else 'MISSED'})")
    if "verdict" in r:
        v = r["verdict"]
        print(f"{'the verdict step':24s} {v['median_s'] * 1e3:9.1f} ms   (calibrate + verdict: "
              f"{v['with_calibrate_ratio']:.2f}x OpenCV, target <= {RICHER_MAX_RATIO}x: "
              f"{'ok' if v['meets_target'] else 'MISSED'})")
        print("  where the verdict's time goes: " + ", ".join(
            f"{k} {t * 1e3:.1f} ms" for k, t in sorted(v["parts_s"].items(), key=lambda kv: -kv[1]) if t >= 5e-4))
    if "dtscal" in r:
        mark = "ok" if r["dtscal"]["meets_target"] else "MISSED"
        print(f"target: dtscal calibrate() < {r['target_s']} s: {mark}")
    else:
        print("dtscal calibrate() not available: only the baseline was timed")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", action="store_true", help="print the numbers as JSON")
    ap.add_argument("--check", action="store_true", help="exit 1 if the target is missed")
    ap.add_argument("--repeats", type=int, default=5, help="runs per timing (median)")
    args = ap.parse_args(argv)
    r = run(args.repeats)
    if args.json:
        print(json.dumps(r, indent=2))
    else:
        print_report(r)
    if args.check and not r.get("dtscal", {}).get("meets_target", False):
        print("target missed (or dtscal calibrate() unavailable)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
