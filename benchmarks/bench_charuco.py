"""Benchmark: ChArUco against the chessboard on the same poses (issue 32, item 7).

The hand-held sweep of the recorded session (``dtscal_lib.synth``'s key poses, rendered noise-free but for
the sensor noise, no motion blur) is drawn twice through the Duckiebot camera: once with a chessboard of
8x6 squares of 45 mm, once with the ChArUco board of the bundled ChArUco recording (the same squares, 27 mm
DICT_4X4_50 markers) and, for the corner accuracy only, with 34 mm markers. Printed, side by side:

* views found and corners found per board (a ChArUco board counts partly visible views);
* the corners' error against the exact projection (rms, p99, corners off by more than 0.5 px);
* the kit's calibration of each (every view found, plumb_bob): focal lengths' and principal point's error
  against the rendering camera, in percent and pixels;
* detection time per frame, ChArUco (OpenCV's detector and the kit's refinement) against the chessboard
  (the kit's detector), as a ratio measured in the same run.

Run::

    .venv/bin/python benchmarks/bench_charuco.py [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dtscal_lib import synth  # noqa: E402
from dtscal_lib.boards import Board, CharucoBoard  # noqa: E402
from dtscal_lib.calibration import calibrate  # noqa: E402
from dtscal_lib.detect import detect_board  # noqa: E402


def sweep_poses():
    return [k[2] for k in synth._SWEEP if k[2] is not None]


def run_board(board, renderer, poses, seed=3):
    cam = renderer.camera
    errs, obj, img, t_detect, n_frames = [], [], [], 0.0, 0
    for i, p in enumerate(poses):
        R, t = synth._pose_from_params(cam, board, p)
        frame, corners, _ = synth.render_view(cam, board, synth._rvec(R), t, rng=np.random.default_rng([seed, i]),
                                              renderer=renderer)
        if corners is None:
            continue
        n_frames += 1
        t0 = time.perf_counter()
        det = detect_board(frame, board)
        t_detect += time.perf_counter() - t0
        if not det.found:
            continue
        ids = det.ids if det.ids is not None else np.arange(board.n_corners)
        # a chessboard's corners may come in the reverse order of the truth (the board turned half round)
        truth = corners[ids]
        if det.ids is None and np.linalg.norm(det.corners - truth[::-1], axis=1).mean() < \
                np.linalg.norm(det.corners - truth, axis=1).mean():
            truth = truth[::-1]
            ids = ids[::-1]
        errs.extend(np.linalg.norm(det.corners - truth, axis=1))
        obj.append(board.object_points()[ids])
        img.append(det.corners)
    errs = np.array(errs)
    res = calibrate(obj, img, cam.size)
    K0 = cam.K
    return {
        "views": len(obj), "frames_with_board": n_frames, "corners": int(len(errs)),
        "corner_rms_px": round(float(np.sqrt(np.mean(errs ** 2))), 4),
        "corner_p99_px": round(float(np.percentile(errs, 99)), 4),
        "corners_over_0_5_px": int((errs > 0.5).sum()),
        "fx_err_pct": round(100 * float(res.K[0, 0] / K0[0, 0] - 1), 4),
        "fy_err_pct": round(100 * float(res.K[1, 1] / K0[1, 1] - 1), 4),
        "cx_err_px": round(float(res.K[0, 2] - K0[0, 2]), 3),
        "cy_err_px": round(float(res.K[1, 2] - K0[1, 2]), 3),
        "detect_ms_per_frame": round(1000 * t_detect / max(n_frames, 1), 2),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    renderer = synth.make_renderer()
    poses = sweep_poses()
    boards = {
        "chessboard 8x6 x 45 mm": Board(7, 5, 0.045),
        "charuco 8x6 x 45 mm, 27 mm markers": synth.CHARUCO_BOARD,
        "charuco 8x6 x 45 mm, 34 mm markers": CharucoBoard.from_squares(8, 6, 0.045, 0.034, "4x4_50"),
    }
    out = {name: run_board(b, renderer, poses) for name, b in boards.items()}
    chess = out["chessboard 8x6 x 45 mm"]["detect_ms_per_frame"]
    for row in out.values():
        row["detect_ratio_to_chessboard"] = round(row["detect_ms_per_frame"] / chess, 2)
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    keys = list(next(iter(out.values())))
    print(f"{'':34s}" + "".join(f"{k:>22s}" for k in keys))
    for name, row in out.items():
        print(f"{name:34s}" + "".join(f"{row[k]!s:>22s}" for k in keys))
    return 0


if __name__ == "__main__":
    sys.exit(main())
