"""Benchmark: verdicts on random subsets of real photographs, clean and with planted defects (issue 31).

Material: OpenCV's real sample photographs (``data/real/opencv-samples``, left and right, 13 views each, 9x6
board, 30 mm), the kit's own corners. For each camera: the full set and ``--subsets`` random subsets of 6-10
views, each calibrated as ``dtscal calibrate-intrinsics`` does and judged (the session's verdict step).

Printed:

1. per camera, the verdicts of the clean subsets (counts of good / doubtful / bad) and the distribution of
   the two numbers the robot's limits read: the mean 1-sigma projection uncertainty where the robot looks
   (``robot_view_sigma``, the lower half of the image) and at the image corners; and, for every column or
   row offset named on a clean subset, the projection shift its removal makes where the robot looks
   (``robot_shift``): the data behind ``robot_view_sigma_doubtful``, ``robot_view_sigma_bad`` and
   ``robot_shift_bad`` (``dtscal_lib.limits``). None may be "bad".
2. the sensitivity table: a planted defect (a shifted lower half of one view, cut along a grid line or across
   it; a bent column, column 0 moved outwards in 5 of the views; one displaced corner, column 2 row 2) of each
   size, named in n of m subsets of 10 views of the right set, and how often the verdict is "bad".

Run::

    .venv/bin/python benchmarks/bench_verdict_subsets.py [--subsets 40] [--seed 0]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

from dtscal_lib import pipeline  # noqa: E402
from dtscal_lib.boards import parse_board  # noqa: E402
from dtscal_lib.calibration import calibrate  # noqa: E402
from dtscal_lib.rules import grid_indices, robot_view_shift  # noqa: E402
from dtscal_lib.session import assess_quality, calibrate_without_outlier_views  # noqa: E402
from dtscal_lib.uncertainty import robot_view_sigma  # noqa: E402

REAL = HERE.parent / "data" / "real" / "opencv-samples"
BOARD = parse_board("9x6", 0.03)


def views(side: str):
    res = pipeline.calibrate_intrinsics(REAL / side, board=BOARD).result
    obj = [np.asarray(o, float)[:, :2] for o in res.object_points]
    img = [np.asarray(p, float).reshape(-1, 2) for p in res.image_points]
    return obj, img, res.image_size


def judge(obj, img, size):
    res, _ = calibrate_without_outlier_views(obj, img, size)
    return res, assess_quality(res)


def shift_lower_half(obj, img, view, px, by_grid=True):
    """The lower half of one view moved ``px`` to the right: the board's rows 3-5 (a step along a grid line), or
    (``by_grid=False``) the corners below the view's median pixel row (a cut across the grid when it is tilted)."""
    img = [p.copy() for p in img]
    p = img[view]
    lower = grid_indices(obj[view])[:, 1] >= 3 if by_grid else p[:, 1] > np.median(p[:, 1])
    p[lower, 0] += px
    return img


def bend_column(obj, img, views, px, column=0):
    """Column ``column`` moved ``px`` outwards in ``views`` (benchmarks/bench_verdict.py's planted bent column)."""
    from bench_verdict import _shift_column

    return _shift_column(obj, img, column, views, px)


def move_corner(obj, img, view, px, column=2, row=2):
    img = [p.copy() for p in img]
    g = grid_indices(obj[view])
    i = np.flatnonzero((g[:, 0] == column) & (g[:, 1] == row))[0]
    img[view][i] += px / np.sqrt(2)
    return img


def named(q, kind: str, view=None) -> bool:
    if isinstance(q, str):
        return False
    for f in q.findings:
        if kind == "view" and f.code in ("shifted_part", "outlier_views") and view in f.views:
            return True
        if kind == "column" and f.code == "column_offset":
            return True
        if kind == "corner" and f.code == "outlier_corners" and "column 2, row 2" in f.message:
            return True
    return False


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--subsets", type=int, default=40)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--sizes", type=int, default=8, help="planted subsets per defect size")
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    data = {side: views(side) for side in ("left", "right")}
    print("1. clean: full sets and random subsets of 6-10 views")
    for side, (obj, img, size) in data.items():
        tally = {"good": 0, "doubtful": 0, "bad": 0, "none": 0}
        rv, corners, shifts, bad = [], [], [], []
        sets = [list(range(len(obj)))] + [sorted(rng.choice(len(obj), int(rng.integers(6, 11)), replace=False))
                                          for _ in range(args.subsets)]
        for k, sel in enumerate(sets):
            res, q = judge([obj[i] for i in sel], [img[i] for i in sel], size)
            if isinstance(q, str):
                tally["none"] += 1
                continue
            tally[q.verdict] += 1
            if q.uncertainty is not None:
                rv.append(robot_view_sigma(q.uncertainty, size))
                corners.append(q.uncertainty.corner_mean)
            for f in q.findings:
                if f.code in ("column_offset", "row_offset", "shifted_part"):
                    shifts.append(f"{f.code} {f.severity} ({f.message.split('Leaving it out moves')[-1][-60:]})")
            if q.verdict == "bad":
                bad.append((k, len(sel), [f"{f.code}: {f.message[:90]}" for f in q.findings if f.severity == "bad"]))
            if k == 0:
                print(f"  {side} full set ({len(sel)} views): {q.verdict}; robot view {rv[-1]:.2f} px, corners "
                      f"{corners[-1]:.2f} px")
        rv_a, c_a = np.array(rv), np.array(corners)
        print(f"  {side}: {len(sets)} sets: " + ", ".join(f"{k} {v}" for k, v in tally.items()))
        print(f"    robot-view 1-sigma px: median {np.median(rv_a):.2f}, 95 % {np.quantile(rv_a, 0.95):.2f}, "
              f"max {rv_a.max():.2f}")
        print(f"    image-corner 1-sigma px: median {np.nanmedian(c_a):.2f}, 95 % {np.nanquantile(c_a, 0.95):.2f}, "
              f"max {np.nanmax(c_a):.2f}")
        print(f"    line offsets and shifted parts named on clean sets: {len(shifts)}")
        for s in shifts:
            print(f"      {s}")
        for k, n, why in bad:
            print(f"    BAD set {k} ({n} views): {why}")
    print("\n2. sensitivity: planted defect -> named in n of m random 10-view subsets (bad: verdict 'bad')")
    obj_all, img_all, size = data["right"]
    cases = [("shifted lower half of one view (view 3): the board's rows 3-5", "view", [0.2, 0.3, 0.5, 0.7, 1.0]),
             ("shifted lower half of one view (view 3): below its median pixel row", "cut", [0.3, 0.5, 1.0, 1.5, 2.0]),
             ("bent column 0 (5 views)", "column", [0.1, 0.2, 0.3, 0.5, 1.0]),
             ("displaced corner (column 2, row 2)", "corner", [0.2, 0.3, 0.5, 1.0, 2.0])]
    for title, kind, sizes in cases:
        print(f"  {title}")
        for px in sizes:
            hits = bads = 0
            for _ in range(args.sizes):
                sel = sorted(rng.choice(len(obj_all), 10, replace=False))
                obj = [obj_all[i] for i in sel]
                img = [img_all[i] for i in sel]
                if kind in ("view", "cut"):
                    img = shift_lower_half(obj, img, 3, px, by_grid=kind == "view")
                elif kind == "column":
                    img = bend_column(obj, img, {0, 2, 4, 6, 8}, px)
                else:
                    img = move_corner(obj, img, 3, px)
                res, q = judge(obj, img, size)
                hits += named(q, "view" if kind == "cut" else kind, 3)
                bads += (not isinstance(q, str)) and q.verdict == "bad"
            print(f"    {px:4.1f} px: named {hits} of {args.sizes}, bad {bads} of {args.sizes}")
    _ = (calibrate, robot_view_shift)


if __name__ == "__main__":
    main()
