"""Benchmark: ``calibrate-intrinsics --cross-validate``'s ratios beside mrcal's, for the same splits.

For each seeded random split of OpenCV's real left and right photographs (``data/real/opencv-samples``, the
kit's corners, 13 views, 9x6 board of 30 mm) into two halves (``dtscal_lib.compare.half_splits``), both the
kit and mrcal 2.2 (Debian's python3-mrcal on /usr/bin/python3, ``benchmarks/mrcal_xval_helper.py``) calibrate
each half (plumb_bob with k3 = 0, mrcal's LENSMODEL_OPENCV4: the same parameters) and divide the projection
difference of the halves (after the uncertainty-weighted aligning rotation at infinity) by the predicted
1-sigma of that difference, sqrt(sigma_A^2 + sigma_B^2). Printed: the largest ratio at the four image
corners and over the central two thirds of the image, kit beside mrcal. The kit's sigma is its honest one
(at least the noise model's, more where the views disagree: docs/uncertainty.md), mrcal's its noise model,
so the kit's ratios are expected at or below mrcal's (bench_mrcal.py: the kit's projection sigma is
1.27-2.58x mrcal's on these sets).

Run::

    .venv/bin/python benchmarks/bench_cross_validate.py [--splits 5] [--json]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

from bench_compare import corners  # noqa: E402
from bench_mrcal import BOARD, MRCAL_PYTHON, MrcalMissing, _clean_env, mrcal_corners, mrcal_problem  # noqa: E402

from dtscal_lib.compare import cross_validate  # noqa: E402

HELPER = HERE / "mrcal_xval_helper.py"


class _Views:
    """Enough of a calibration result for ``bench_mrcal.mrcal_corners``."""

    def __init__(self, obj, img):
        self.object_points, self.image_points = obj, img


def run(side: str, splits: int) -> dict:
    obj, img, size = corners(side)
    cv = cross_validate(obj, img, size, splits=splits)
    pairs = [[mrcal_corners(_Views([obj[i] for i in h], [img[i] for i in h]), BOARD[1]).tolist() for h in split]
             for split in cv.splits]
    problem = mrcal_problem()
    if problem:
        raise MrcalMissing(problem)
    req = {"image_size": list(size), "spacing": BOARD[1], "lensmodel": "LENSMODEL_OPENCV4",
           "focal_estimate": float(size[0]), "pairs": pairs}
    p = subprocess.run([MRCAL_PYTHON, str(HELPER)], input=json.dumps(req), env=_clean_env(), capture_output=True,
                       text=True, timeout=900, check=False)
    try:
        m = json.loads(p.stdout.strip().splitlines()[-1])
    except (IndexError, json.JSONDecodeError):
        raise RuntimeError(f"mrcal helper failed (exit {p.returncode}): {p.stderr.strip()[-2000:]}") from None
    if "error" in m:
        raise MrcalMissing(m["error"])
    mr = [{"corners": float(np.nanmax(r["corners"])) if np.isfinite(r["corners"]).any() else float("nan"),
           "inside": r["inside"], "max_px": r["max_px"]} for r in m["ratios"]]
    return {"side": side, "splits": cv.to_dict()["splits"], "kit": cv.ratios(), "mrcal": mr}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--splits", type=int, default=5)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    out = [run(side, args.splits) for side in ("left", "right")]
    if args.json:
        print(json.dumps(out))
        return 0
    for r in out:
        print(f"{r['side']}: half-set difference / predicted sigma (kit | mrcal)")
        for i, (k, m) in enumerate(zip(r["kit"], r["mrcal"])):
            print(f"  split {i}: corners {k['corners']:5.2f} | {m['corners']:5.2f}   inside {k['inside']:5.2f} | "
                  f"{m['inside']:5.2f}   max diff {k['max_px']:7.2f} | {m['max_px']:7.2f} px")
    return 0


if __name__ == "__main__":
    sys.exit(main())
