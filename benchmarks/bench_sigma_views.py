"""Benchmark: does the reported sigma cover as often as it says, at any number of views? (issue 21)

Material: OpenCV's real sample photographs (``data/real/opencv-samples``, left and right, 13 views each,
9x6 board, 30 mm), the kit's own corners. For V = 4, 5, 6, 8 and 13 views, ``--subsets`` random subsets
of V views per camera (seeded) are calibrated as ``dtscal calibrate-intrinsics`` does (plumb_bob, k3 = 0);
for each of fx, fy, cx, cy the subset's value is compared with the 13-view value: covered when within the
subset's reported 1 sigma (``result.std``). An honest sigma covers about 68 % of the time (a little more
at 13 views, where the subset is the reference itself: 100 %). Printed: the coverage per V, and the
reported sigma divided by the spread of the subsets' values (1 when honest).

Run::

    .venv/bin/python benchmarks/bench_sigma_views.py [--subsets 30] [--seed 0]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from dtscal_lib import pipeline  # noqa: E402
from dtscal_lib.boards import parse_board  # noqa: E402
from dtscal_lib.calibration import calibrate  # noqa: E402
from dtscal_lib.errors import DtscalError  # noqa: E402

REAL = HERE.parent / "data" / "real" / "opencv-samples"
CORE = ("fx", "fy", "cx", "cy")
VIEWS = (4, 5, 6, 8, 13)


def coverage(side: str, n_views: int, subsets: int, seed: int = 0) -> dict:
    """``{"covered": share, "n": count, "sigma_over_spread": ratio, "method": a std_method}`` for V views."""
    full = pipeline.calibrate_intrinsics(REAL / side, board=parse_board("9x6", 0.03)).result
    ref = np.array([full.K[0, 0], full.K[1, 1], full.K[0, 2], full.K[1, 2]])
    rng = np.random.default_rng(seed)
    hits, vals, sig, method = [], [], [], ""
    for _ in range(subsets if n_views < full.n_views else 1):
        pick = sorted(rng.choice(full.n_views, n_views, replace=False))
        try:
            r = calibrate([full.object_points[i] for i in pick], [full.image_points[i] for i in pick],
                          full.image_size, model=full.model)
        except DtscalError:
            continue
        v = np.array([r.K[0, 0], r.K[1, 1], r.K[0, 2], r.K[1, 2]])
        s = np.array([r.std[k] for k in CORE])
        hits.append(np.abs(v - ref) <= s)
        vals.append(v)
        sig.append(s)
        method = r.std_method
    vals, sig = np.array(vals), np.array(sig)
    spread = np.sqrt(((vals - ref) ** 2).mean(axis=0)) if len(vals) > 1 else np.full(4, np.nan)
    return {"covered": float(np.mean(hits)), "n": len(hits), "sigma_over_spread": (sig.mean(axis=0) / spread).tolist(),
            "method": method}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--subsets", type=int, default=30)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    print(f"{'camera':7s} {'views':>5s} {'subsets':>7s} {'covered':>8s}  sigma / spread (fx fy cx cy)   method")
    for side in ("left", "right"):
        for V in VIEWS:
            c = coverage(side, V, a.subsets, a.seed)
            print(f"{side:7s} {V:5d} {c['n']:7d} {100 * c['covered']:7.0f} %  "
                  f"{' '.join(f'{x:5.2f}' for x in c['sigma_over_spread']):28s} {c['method'][:60]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
