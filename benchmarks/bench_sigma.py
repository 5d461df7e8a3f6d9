"""Benchmark: which standard deviation of the intrinsics is honest.

Two tests of each estimate of sigma(fx, fy, cx, cy) (see ``dtscal_lib/covariance.py``):

1. **Real photographs** (``data/real/opencv-samples``, 13 views per camera, the kit's corners): the
   named baseline is a brute-force jackknife over views (13 full re-calibrations, each without one
   view). Printed: each estimate divided by it. The acceptance is a factor 1.5 either way.
2. **Synthetic views with exactly Gaussian noise** (the noise model is right there): the named
   baseline is the true spread of the estimates over repeated noise draws on the same poses.
   Printed: the mean estimate divided by it, for 6 and 13 views. An estimate much above 1 here is
   pessimistic where nothing is wrong.

Estimates: the noise model ``sigma^2 (J^T J)^-1`` (OpenCV's ``stdDeviationsIntrinsics``); the same
inflated by the ratio of the residual to the model-free corner noise; the plain sandwich over views
(CR1); the Bell-McCaffrey sandwich (CR2); the one-step jackknife; and what the kit reports (the
larger of the noise model and CR2 in every direction).

Run::

    .venv/bin/python benchmarks/bench_sigma.py [--draws 25] [--quick]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from dtscal_lib import camera, duckietown as dt, pipeline, quality  # noqa: E402
from dtscal_lib.boards import DUCKIETOWN_BOARD, parse_board  # noqa: E402
from dtscal_lib.calibration import calibrate  # noqa: E402
from dtscal_lib.covariance import honest_intrinsic_covariance, robust_intrinsic_covariance  # noqa: E402

REAL = HERE.parent / "data" / "real" / "opencv-samples"
NAMES = ("noise model", "x fit/noise", "sandwich CR1", "sandwich CR2", "jackknife 1-step", "kit")


def estimates(res) -> dict[str, np.ndarray]:
    """sigma of fx, fy, cx, cy by every estimate, (4,) each."""
    b = res.normal_blocks()
    Sv = b.schur_views()
    S = Sv.sum(axis=0)
    Si = np.linalg.inv(S)
    V = b.n_views
    noise = b.sigma2 * Si
    corner, _ = quality.corner_noise(res.object_points, res.image_points)
    cr1 = Si @ (b.g.T @ b.g) @ Si * V / (V - 1)
    d = np.linalg.solve(S[None] - Sv, b.g[:, :, None])[:, :, 0]
    dm = d - d.mean(axis=0)
    jack = (V - 1) / V * dm.T @ dm
    kit = honest_intrinsic_covariance(b)[0]
    sd = {"noise model": noise, "sandwich CR1": cr1, "sandwich CR2": robust_intrinsic_covariance(b),
          "jackknife 1-step": jack, "kit": kit}
    out = {k: np.sqrt(np.diag(v))[:4] for k, v in sd.items()}
    out["x fit/noise"] = out["noise model"] * max(1.0, res.sigma / corner)
    return out


def brute_jackknife(res) -> np.ndarray:
    theta = []
    for v in range(res.n_views):
        keep = [i for i in range(res.n_views) if i != v]
        r = res.refit([res.object_points[i] for i in keep], [res.image_points[i] for i in keep])
        theta.append([r.K[0, 0], r.K[1, 1], r.K[0, 2], r.K[1, 2]])
    theta = np.asarray(theta)
    V = len(theta)
    return np.sqrt((V - 1) / V * ((theta - theta.mean(axis=0)) ** 2).sum(axis=0))


def real_table() -> None:
    print("real photographs: estimate / brute-force jackknife over views (fx fy cx cy); 1.5x either way passes")
    for side in ("left", "right"):
        res = pipeline.calibrate_intrinsics(REAL / side, board=parse_board("9x6", 0.03)).result
        jack = brute_jackknife(res)
        est = estimates(res)
        corner, _ = quality.corner_noise(res.object_points, res.image_points)
        print(f"  {side}: {res.n_views} views, residual sigma {res.sigma:.3f} px = {res.sigma / corner:.2f} x corner "
              f"noise; jackknife {' '.join(f'{x:.3f}' for x in jack)} px")
        for name in NAMES:
            r = est[name] / jack
            flag = "" if np.all((r < 1.5) & (r > 1 / 1.5)) else "   <- outside 1.5x"
            print(f"    {name:18s} {' '.join(f'{x:5.2f}' for x in r)}{flag}")


def synthetic_table(draws: int, views=(6, 13)) -> None:
    print(f"synthetic, Gaussian noise 0.3 px, the true lens model: mean estimate / true spread over {draws} draws")
    obj = DUCKIETOWN_BOARD.object_points()
    for V in views:
        rng = np.random.default_rng(V)
        exact = []
        while len(exact) < V:
            r = [*rng.uniform(-0.5, 0.5, 2), rng.uniform(-0.3, 0.3)]
            t = [rng.uniform(-0.25, 0.05), rng.uniform(-0.17, 0.0), rng.uniform(0.22, 0.35)]
            p = camera.project_points(obj, r, t, dt.default_K(), dt.default_dist())
            if p.min() > 5 and p[:, 0].max() < 635 and p[:, 1].max() < 475:
                exact.append(p)
        thetas, ests = [], {k: [] for k in NAMES}
        for _ in range(draws):
            res = calibrate([obj] * V, [p + rng.normal(0.0, 0.3, p.shape) for p in exact], dt.IMAGE_SIZE)
            thetas.append(res.intrinsic_vector()[:4])
            for k, v in estimates(res).items():
                ests[k].append(v)
        true = np.std(thetas, axis=0, ddof=1)
        print(f"  {V} views: true spread {' '.join(f'{x:.3f}' for x in true)} px")
        for name in NAMES:
            print(f"    {name:18s} {' '.join(f'{x:5.2f}' for x in np.mean(ests[name], axis=0) / true)}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--draws", type=int, default=25, help="noise draws per synthetic case")
    ap.add_argument("--quick", action="store_true", help="the real photographs only")
    args = ap.parse_args(argv)
    real_table()
    if not args.quick:
        synthetic_table(args.draws)
    return 0


if __name__ == "__main__":
    sys.exit(main())
