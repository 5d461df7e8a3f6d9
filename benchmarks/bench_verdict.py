"""Benchmark: the verdict's boundaries on real photographs, clean and with planted defects (issue 21).

Material: OpenCV's real sample photographs (``data/real/opencv-samples``, left and right, 13 views each,
9x6 board, 30 mm), the kit's own corners, calibrated as ``dtscal calibrate-intrinsics`` does.

Printed per camera:

* the residual sigma per coordinate over the model-free corner noise, and the share of the residual above
  the noise, ``(s^2 - s_c^2) / (s^2 - n^2)``, that each richer model fitted to the same corners explains
  (k3, OpenCV's 8-coefficient rational, mrcal's two-parameter board warp; ``dtscal_lib.richer``), with the
  warp in mm: the data behind ``lens_share`` and ``unexplained_ratio_doubtful`` (``dtscal_lib.limits``);
* the longest residual in robust sigma, clean and with one corner moved by 2 px: the data behind
  ``outlier_corner_z``;
* the verdict and its findings, clean and for each planted defect: a bent column (column 0 moved 1.5 px
  outwards in 9 views), a shifted view (1 px of noise on view 5), one corner moved by 2 px, too few views
  (the first 4).

Run::

    .venv/bin/python benchmarks/bench_verdict.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from dtscal_lib import pipeline, quality  # noqa: E402
from dtscal_lib.boards import parse_board  # noqa: E402
from dtscal_lib.richer import candidates, excess_share, fit_richer  # noqa: E402

REAL = HERE.parent / "data" / "real" / "opencv-samples"


def _shift_column(obj, img, column, views, px):
    out = []
    for v, (o, p) in enumerate(zip(obj, img)):
        p = np.array(p, dtype=float)
        if v in views:
            g = quality.grid_indices(o)
            inner = column + (1 if column == 0 else -1)
            for i in np.flatnonzero(g[:, 0] == column):
                j = np.flatnonzero((g[:, 0] == inner) & (g[:, 1] == g[i, 1]))[0]
                d = p[i] - p[j]
                p[i] += px * d / np.linalg.norm(d)
        out.append(p)
    return out


def _longest(res) -> float:
    e = np.concatenate(quality.residuals(res))
    return float(np.linalg.norm(e, axis=1).max() / (1.4826 * np.median(np.abs(e))))


def planted(res) -> dict:
    """The planted defects of a clean result: name -> (object points, image points)."""
    obj = [np.asarray(o, float) for o in res.object_points]
    img = [np.asarray(p, float).reshape(-1, 2).copy() for p in res.image_points]
    rng = np.random.default_rng(1)
    shifted = [p.copy() for p in img]
    shifted[5] = shifted[5] + rng.normal(0, 1.0, shifted[5].shape)
    corner = [p.copy() for p in img]
    corner[3][20] += [2.0 / np.sqrt(2), 2.0 / np.sqrt(2)]
    return {"bent column": (obj, _shift_column(obj, img, 0, range(9), 1.5)), "shifted view": (obj, shifted),
            "one corner 2 px": (obj, corner), "4 views": (obj[:4], img[:4])}


def main() -> int:
    for side in ("left", "right"):
        res = pipeline.calibrate_intrinsics(REAL / side, board=parse_board("9x6", 0.03)).result
        q = res.quality()
        print(f"\n== {side}: {res.n_views} views, sigma {res.sigma:.4f} px, corner noise {q.noise_sigma:.4f} px, "
              f"ratio {res.sigma / q.noise_sigma:.2f}")
        for name in candidates(res) + ["warp"]:
            f = fit_richer(res, name)
            extra = f", warp {1000 * f.warp[0]:+.4f} {1000 * f.warp[1]:+.4f} mm" if name == "warp" else ""
            print(f"  {name:9s} sigma {f.sigma:.4f} px, share of the excess "
                  f"{100 * excess_share(res.sigma, f.sigma, q.noise_sigma):5.1f} %{extra}")
        print(f"  longest residual {_longest(res):.2f} robust sigma; image corners {q.uncertainty.corner_mean:.2f} px")
        print(f"  clean: {q.verdict} {[(f.code, f.severity) for f in q.findings]}")
        for name, (obj, img) in planted(res).items():
            r = res.refit(obj, img)
            qq = r.quality()
            more = f" (longest residual {_longest(r):.1f} robust sigma)" if name.startswith("one corner") else ""
            print(f"  {name}: {qq.verdict} {[(f.code, f.severity) for f in qq.findings]}{more}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
