"""Benchmark: corner detection time, detection rate and accuracy against ROS's detector.

Baseline, measured in the same run: ROS ``camera_calibration``'s call, OpenCV's classic
``findChessboardCorners(ADAPTIVE_THRESH | NORMALIZE_IMAGE | FAST_CHECK)`` on the full
frame (``dtscal_lib.detect.detect_board_ros`` adds the same ordering / cornerSubPix /
border rule as ours, which cost well under a millisecond).

Part 1 (timing): median time per 640x480 frame for one cluttered frame without a board
and one realistic Duckiebot frame with a board. Target: <= 15 ms for both.

Part 2 (quality, skipped with ``--quick``): a set of rendered frames with exact ground
truth (Duckiebot barrel distortion, blur, noise, JPEG, cluttered backgrounds, boards
from 0.25 m to 1.2 m away) and board-free frames of five clutter kinds: detection rate,
false detections, corner error, time distribution.

Part 3 (if ``data/session`` holds the synthetic recording, skipped with ``--quick``): both
detectors on every frame of ``intrinsics.bag`` against the corners in ``truth.yaml``.

Part 4 (stress set, skipped with ``--quick``): ``synth.render_stress_case`` for every kind and
``--stress-seeds`` seeds: corner error of the kit's refinement (``detect_board_still``) and of
ROS's (``detect_board_ros``: one window of half the smallest spacing) against exact truth.

Part 0 (real photographs, timing; also with ``--quick``): the kit's ``detect_board`` against OpenCV's
sample pipeline (``findChessboardCorners`` with its default flags + ``cornerSubPix`` 11x11) on every
photograph of ``data/real`` (9x6, 640x480), alternating the two on each image; per image the shortest of
``--repeats`` runs, in CPU time of this process (both are single-threaded here; CPU time is what a loaded
machine does not inflate) and in wall time; the median over the images and the kit/OpenCV ratio.
Target: ratio <= 0.7.

Part 5 (real photographs, skipped with ``--quick``): OpenCV's sample photographs in
``data/real`` calibrated (``cv2.calibrateCamera``, k3 fixed) from the kit's corners and from
OpenCV's sample pipeline (``cornerSubPix`` 11x11) and ``findChessboardCornersSB``.
``--figure PNG`` draws, for one real photograph and one stress frame, the kit's corners (green)
and the ROS / sample-pipeline corners (red) on 2x crops of the outer column.

Run::

    .venv/bin/python benchmarks/bench_detect.py            # tables
    .venv/bin/python benchmarks/bench_detect.py --json     # numbers as JSON
    .venv/bin/python benchmarks/bench_detect.py --check    # exit 1 if the target is missed
    .venv/bin/python benchmarks/bench_detect.py --figure benchmarks/detect_real_boards.png
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common import FrameRenderer, clutter_image, look_at_pose, median_time, random_visible_pose  # noqa: E402

from dtscal_lib.detect import detect_board, detect_board_ros, order_corners  # noqa: E402

TARGET_MS = 15.0
#: the kit's detection with a board on real photographs, as a fraction of OpenCV's sample pipeline's time
TARGET_REAL_RATIO = 0.7
KINDS = ("tiles", "rects", "office", "noise", "mixed")


def timing_frames(renderer: FrameRenderer, seed: int = 3):
    """The two timing frames: a cluttered board-free frame and a realistic board frame."""
    rng = np.random.default_rng(seed)
    # "rects": hundreds of boxes, the classic detector's slow case (its fast check passes)
    empty = renderer.render_empty(clutter_image(rng, kind="rects"), rng).image
    r, t = look_at_pose(renderer.board, 0.5, 0.35, -0.25, 0.2, (0.04, 0.02))
    board = renderer.render(r, t, clutter_image(rng, kind="office"), rng, blur=1.0, noise=3.0,
                            jpeg_quality=80)
    return empty, board


def part_timing(renderer: FrameRenderer, repeats: int) -> dict:
    empty, board = timing_frames(renderer)
    out = {}
    for name, img in (("no board (cluttered)", empty), ("board (Duckiebot lens)", board.image)):
        ours = median_time(detect_board, img, repeats=repeats)
        ros = median_time(detect_board_ros, img, repeats=repeats)
        d = detect_board(img)
        out[name] = {"ours_ms": ours * 1e3, "ros_ms": ros * 1e3, "speedup": ros / ours,
                     "found": bool(d.found), "target_ms": TARGET_MS, "meets_target": ours * 1e3 <= TARGET_MS}
    return out


def part_real_timing(repeats: int) -> dict:
    """Kit vs OpenCV's sample pipeline on the real photographs: median CPU and wall ms, ratios (see Part 0)."""
    import cv2

    from dtscal_lib.boards import Board

    board = Board(cols=9, rows=6, square=0.03)
    files = sorted(REAL.glob("*/*.jpg"))
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)

    def opencv(g):
        ok, c = cv2.findChessboardCorners(g, board.pattern_size, None)
        if ok:
            cv2.cornerSubPix(g, c, (11, 11), (-1, -1), crit)
        return ok

    def kit(g):
        return detect_board(g, board).found

    best = {"kit": {"cpu": [], "wall": []}, "opencv": {"cpu": [], "wall": []}}
    found = {"kit": 0, "opencv": 0}
    for f in files:
        g = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        per = {name: [np.inf, np.inf] for name in best}
        for name, fn in (("kit", kit), ("opencv", opencv)):
            found[name] += bool(fn(g))  # also the warm-up
        for _ in range(repeats):
            for name, fn in (("kit", kit), ("opencv", opencv)):
                c0, w0 = time.process_time(), time.perf_counter()
                fn(g)
                per[name][0] = min(per[name][0], time.process_time() - c0)
                per[name][1] = min(per[name][1], time.perf_counter() - w0)
        for name in best:
            best[name]["cpu"].append(per[name][0] * 1e3)
            best[name]["wall"].append(per[name][1] * 1e3)
    out = {name: {"images": len(files), "found": found[name],
                  "cpu_ms_median": float(np.median(v["cpu"])), "wall_ms_median": float(np.median(v["wall"]))}
           for name, v in best.items()}
    out["ratio_cpu"] = out["kit"]["cpu_ms_median"] / out["opencv"]["cpu_ms_median"]
    out["ratio_wall"] = out["kit"]["wall_ms_median"] / out["opencv"]["wall_ms_median"]
    out["target_ratio"] = TARGET_REAL_RATIO
    out["meets_target"] = out["ratio_cpu"] <= TARGET_REAL_RATIO
    out["kit_time_goes_to"] = _where_detection_time_goes(kit, files)
    return out


#: the steps of the kit's detector whose own share of the time is printed (dtscal_lib/detect/)
DETECT_STEPS = ("board_regions", "_classic", "findChessboardCorners", "order_corners", "refine_corners_checked",
                "cornerSubPix", "grid_residuals", "grid_disagreement", "_saddle_lattice", "to_gray")


def _where_detection_time_goes(kit, files) -> dict:
    """The kit's detection of every photograph under cProfile: cumulative ms per image of its main steps (the
    share of each, so that a missed goal says where the time goes)."""
    import cProfile
    import pstats

    import cv2

    grays = [cv2.imread(str(f), cv2.IMREAD_GRAYSCALE) for f in files]
    prof = cProfile.Profile()
    prof.enable()
    for g in grays:
        kit(g)
    prof.disable()
    stats = pstats.Stats(prof).stats
    total = sum(tt for (_, _, _), (_, _, tt, _, _) in stats.items())
    out = {"total_ms_per_image": 1e3 * total / len(grays)}
    for (_, _, name), (_, _, _, ct, _) in stats.items():
        key = next((step for step in DETECT_STEPS if name == step or name.endswith(f".{step}>") or
                    name == f"<built-in method cv2.{step}>"), None)
        if key is not None:
            out[key] = out.get(key, 0.0) + 1e3 * ct / len(grays)
    return out


def print_real_timing(r: dict) -> None:
    print()
    print("Real photographs (data/real, 9x6, 640x480), detection with a board: kit detect_board vs OpenCV "
          "findChessboardCorners + cornerSubPix 11x11, median over the images of each one's fastest run")
    for name in ("kit", "opencv"):
        v = r[name]
        print(f"  {name:7s} found {v['found']}/{v['images']}  CPU {v['cpu_ms_median']:6.2f} ms  "
              f"wall {v['wall_ms_median']:6.2f} ms")
    print(f"  kit / OpenCV: CPU {r['ratio_cpu']:.2f}x, wall {r['ratio_wall']:.2f}x "
          f"(target <= {r['target_ratio']:.2f}x: {'met' if r['meets_target'] else 'MISSED'})")
    w = r.get("kit_time_goes_to")
    if w and not r["meets_target"]:
        steps = sorted(((k, v) for k, v in w.items() if k != "total_ms_per_image"), key=lambda kv: -kv[1])
        print(f"  where the kit's time goes (cProfile, cumulative ms per image of {w['total_ms_per_image']:.1f}, "
              "nested steps overlap): " + ", ".join(f"{k} {v:.1f}" for k, v in steps))


def make_quality_set(renderer: FrameRenderer, n_boards: int, n_empty: int, seed: int = 7):
    rng = np.random.default_rng(seed)
    boards = []
    for k in range(n_boards):
        r, t, _ = random_visible_pose(rng, renderer.board, distance=(0.25, 1.2), max_tilt=0.8, margin=12)
        f = renderer.render(r, t, clutter_image(rng, kind=KINDS[k % len(KINDS)]), rng,
                            blur=rng.uniform(0.5, 1.6), noise=rng.uniform(2, 7),
                            jpeg_quality=int(rng.integers(50, 95)), contrast=rng.uniform(0.4, 0.85))
        boards.append((f.image, f.corners))
    empties = [(KINDS[k % len(KINDS)], renderer.render_empty(clutter_image(rng, kind=KINDS[k % len(KINDS)]), rng).image)
               for k in range(n_empty)]
    return boards, empties


def _timed(fn, img):
    t0 = time.perf_counter()
    d = fn(img)
    return d, time.perf_counter() - t0


def part_quality(renderer: FrameRenderer, n_boards: int, n_empty: int) -> dict:
    boards, empties = make_quality_set(renderer, n_boards, n_empty)
    out = {}
    for name, fn in (("ours", detect_board), ("ros", detect_board_ros)):
        times, errors, found, worst = [], [], 0, []
        found_idx = set()
        for i, (img, truth) in enumerate(boards):
            d, dt = _timed(fn, img)
            times.append(dt)
            if d.corners is not None:  # found, or found but rejected at the border
                found += 1
                found_idx.add(i)
                e = np.linalg.norm(d.corners - order_corners(truth, renderer.board), axis=1)
                errors.append(e)
                worst.append(e.max())
        etimes, false_pos, per_kind = [], 0, {}
        for kind, img in empties:
            d, dt = _timed(fn, img)
            etimes.append(dt)
            false_pos += d.corners is not None
            per_kind.setdefault(kind, []).append(dt * 1e3)
        e = np.concatenate(errors) if errors else np.zeros(0)
        out[name] = {
            "boards_found": found, "boards": len(boards), "found_idx": sorted(found_idx),
            "false_detections": int(false_pos), "empty_frames": len(empties),
            "corner_err_median_px": float(np.median(e)) if e.size else None,
            "corner_err_p95_px": float(np.percentile(e, 95)) if e.size else None,
            "corner_err_max_px": float(e.max()) if e.size else None,
            "frames_with_err_over_1px": int(np.sum(np.array(worst) > 1.0)),
            "board_ms_median": float(np.median(times) * 1e3), "board_ms_p90": float(np.percentile(times, 90) * 1e3),
            "board_ms_max": float(np.max(times) * 1e3),
            "empty_ms_median": float(np.median(etimes) * 1e3), "empty_ms_p90": float(np.percentile(etimes, 90) * 1e3),
            "empty_ms_max": float(np.max(etimes) * 1e3),
            "empty_ms_median_by_kind": {k: float(np.median(v)) for k, v in per_kind.items()},
        }
    ours, ros = set(out["ours"].pop("found_idx")), set(out["ros"].pop("found_idx"))
    out["found_by_ros_only"] = len(ros - ours)
    out["found_by_ours_only"] = len(ours - ros)
    return out


SESSION = Path(__file__).resolve().parents[1] / "data" / "session"


def part_session(session: Path = SESSION) -> dict | None:
    """Both detectors on the synthetic Duckiebot recording, scored against its truth file."""
    bag, truth_file = session / "intrinsics.bag", session / "truth.yaml"
    if not (bag.exists() and truth_file.exists()):
        return None
    import yaml

    from dtscal_lib.sources.bag import BagSource

    truth = {f["index"]: f for f in yaml.safe_load(truth_file.read_text())["intrinsics"]["frames"]}
    rows = {"ours": [], "ros": []}
    for frame in BagSource(bag):
        if frame.image is None:
            continue
        t = truth[frame.index]
        for name, fn in (("ours", detect_board), ("ros", detect_board_ros)):
            d, dt = _timed(fn, frame.image)
            err = None
            if d.corners is not None and t["corners"] is not None:
                exact = order_corners(np.asarray(t["corners"], dtype=np.float64))
                err = float(np.linalg.norm(d.corners - exact, axis=1).max())
            rows[name].append((bool(t["board_visible"]), d.corners is not None, err, dt))
    out = {}
    for name, r in rows.items():
        errs = np.array([x[2] for x in r if x[2] is not None])
        out[name] = {
            "frames": len(r), "board_visible": sum(x[0] for x in r),
            "found_when_visible": sum(1 for x in r if x[0] and x[1]),
            "detections_without_truth": sum(1 for x in r if x[1] and x[2] is None),
            "frame_max_err_median_px": float(np.median(errs)) if errs.size else None,
            "frame_max_err_max_px": float(errs.max()) if errs.size else None,
            "frames_with_err_over_1px": int(np.sum(errs > 1.0)),
            "ms_median": float(np.median([x[3] for x in r]) * 1e3),
            "ms_p90": float(np.percentile([x[3] for x in r], 90) * 1e3),
            "ms_median_no_board": float(np.median([x[3] for x in r if not x[0]] or [np.nan]) * 1e3),
        }
    return out


def print_session(s: dict) -> None:
    o, r = s["ours"], s["ros"]
    print()
    print(f"Synthetic session data/session/intrinsics.bag: {o['frames']} frames, board fully visible in "
          f"{o['board_visible']}")
    rows = [("found when visible", "found_when_visible", "{:d}"),
            ("detections without truth", "detections_without_truth", "{:d}"),
            ("per-frame max error median (px)", "frame_max_err_median_px", "{:.3f}"),
            ("worst corner error (px)", "frame_max_err_max_px", "{:.2f}"),
            ("frames with an error > 1 px", "frames_with_err_over_1px", "{:d}"),
            ("ms median (all frames)", "ms_median", "{:.1f}"),
            ("ms p90 (all frames)", "ms_p90", "{:.1f}"),
            ("ms median (no board visible)", "ms_median_no_board", "{:.1f}")]
    print(f"{'':32s} {'detect_board':>13s} {'ROS call':>10s}")
    for label, key, fmt in rows:
        fo = "-" if o[key] is None else fmt.format(o[key])
        fr = "-" if r[key] is None else fmt.format(r[key])
        print(f"{label:32s} {fo:>13s} {fr:>10s}")


def print_report(timing: dict, quality: dict | None) -> None:
    print("Corner detection, 640x480, median over runs (baseline: ROS findChessboardCorners "
          "ADAPTIVE|NORMALIZE|FAST_CHECK, full frame)")
    print(f"{'frame':26s} {'detect_board':>13s} {'ROS call':>10s} {'ROS/ours':>9s} {'target':>8s}")
    for name, r in timing.items():
        mark = "ok" if r["meets_target"] else "MISSED"
        print(f"{name:26s} {r['ours_ms']:10.1f} ms {r['ros_ms']:7.1f} ms {r['speedup']:8.1f}x "
              f"<= {TARGET_MS:.0f} ms {mark}")
    if quality is None:
        return
    o, r = quality["ours"], quality["ros"]
    print()
    print(f"Rendered set: {o['boards']} board frames (0.25-1.2 m, tilt <= 46 deg, blur, noise, JPEG 50-95), "
          f"{o['empty_frames']} board-free frames")
    rows = [
        ("boards found", "boards_found", "{:d}"),
        ("false detections (no board)", "false_detections", "{:d}"),
        ("corner error median (px)", "corner_err_median_px", "{:.3f}"),
        ("corner error p95 (px)", "corner_err_p95_px", "{:.3f}"),
        ("corner error max (px)", "corner_err_max_px", "{:.2f}"),
        ("frames with an error > 1 px", "frames_with_err_over_1px", "{:d}"),
        ("board frame ms median", "board_ms_median", "{:.1f}"),
        ("board frame ms p90", "board_ms_p90", "{:.1f}"),
        ("board frame ms max", "board_ms_max", "{:.1f}"),
        ("no-board frame ms median", "empty_ms_median", "{:.1f}"),
        ("no-board frame ms p90", "empty_ms_p90", "{:.1f}"),
        ("no-board frame ms max", "empty_ms_max", "{:.1f}"),
    ]
    print(f"{'':30s} {'detect_board':>13s} {'ROS call':>10s}")
    for label, key, fmt in rows:
        fo = "-" if o[key] is None else fmt.format(o[key])
        fr = "-" if r[key] is None else fmt.format(r[key])
        print(f"{label:30s} {fo:>13s} {fr:>10s}")
    print(f"{'no-board ms median by kind':30s}")
    for k in o["empty_ms_median_by_kind"]:
        print(f"  {k:28s} {o['empty_ms_median_by_kind'][k]:13.1f} {r['empty_ms_median_by_kind'][k]:10.1f}")
    print(f"boards found by ROS only: {quality['found_by_ros_only']}, by detect_board only: "
          f"{quality['found_by_ours_only']}")


REAL = Path(__file__).resolve().parents[1] / "data" / "real" / "opencv-samples"


def part_stress(seeds: int) -> dict:
    """Kit and ROS refinement on every stress kind (median and worst corner error, px)."""
    from dtscal_lib import synth
    from dtscal_lib.detect import detect_board_still

    renderers, out = {}, {}
    for kind in synth.STRESS_KINDS:
        cam = synth.stress_camera(kind)
        key = tuple(cam.dist.ravel())
        renderers.setdefault(key, synth.make_renderer(cam))
        row = {"kit": [], "ros": []}
        for seed in range(seeds):
            case = synth.render_stress_case(kind, seed, renderer=renderers[key])
            truth = _canonical(case)
            for name, fn in (("kit", detect_board_still), ("ros", detect_board_ros)):
                d = fn(case.image, case.board)
                e = np.linalg.norm(d.corners - truth, axis=1) if d.found else None
                row[name].append(None if e is None else (float(np.median(e)), float(e.max())))
        out[kind] = {name: {"found": sum(r is not None for r in rows), "cases": len(rows),
                            "median_px_worst_case": max((r[0] for r in rows if r), default=None),
                            "max_px": max((r[1] for r in rows if r), default=None)}
                     for name, rows in row.items()}
    return out


def _canonical(case) -> np.ndarray:
    """Truth in the detector's order, from the pose (the rule of tests/detect_truth.py)."""
    import cv2

    b = case.board
    c = case.corners.reshape(b.rows, b.cols, 2)
    R = cv2.Rodrigues(np.asarray(case.rvec, dtype=np.float64))[0]
    centre = R @ np.array([(b.cols - 1) * b.square / 2, (b.rows - 1) * b.square / 2, 0.0]) + case.tvec
    if float(R[:, 2] @ centre) < 0:
        c = c[:, ::-1]
    if c[0, 0, 1] > c[-1, -1, 1]:
        c = c[::-1, ::-1]
    return c.reshape(-1, 2)


def _opencv_sample_corners(g, window: int = 11):
    import cv2

    ok, c = cv2.findChessboardCorners(g, (9, 6), None)
    if not ok:
        return None
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
    return cv2.cornerSubPix(g, c, (window, window), (-1, -1), crit).reshape(-1, 2)


def part_real() -> dict | None:
    """Calibrations of the real photographs from three corner sources (fx, cx, cy, rms, views)."""
    import cv2

    from dtscal_lib.boards import parse_board
    from dtscal_lib.detect import detect_board_still

    if not REAL.is_dir():
        return None
    board = parse_board("9x6", 0.03)
    obj = board.object_points().astype(np.float32)
    out = {}
    for side in ("left", "right"):
        imgs = [cv2.imread(str(f), cv2.IMREAD_GRAYSCALE) for f in sorted((REAL / side).glob("*.jpg"))]
        sources = {"kit": [], "opencv sample 11x11": [], "findChessboardCornersSB": []}
        for g in imgs:
            d = detect_board_still(g, board)
            if d.found:
                sources["kit"].append(d.corners)
            c = _opencv_sample_corners(g)
            if c is not None:
                sources["opencv sample 11x11"].append(c)
            ok, c = cv2.findChessboardCornersSB(g, (9, 6), flags=cv2.CALIB_CB_ACCURACY)
            if ok:
                sources["findChessboardCornersSB"].append(c.reshape(-1, 2))
        out[side] = {}
        for name, corners in sources.items():
            rms, K, *_ = cv2.calibrateCamera([obj] * len(corners), [c.astype(np.float32) for c in corners],
                                             (640, 480), None, None, flags=cv2.CALIB_FIX_K3)
            out[side][name] = {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2], "rms": rms,
                               "views": len(corners)}
    return out


def print_stress(st: dict) -> None:
    print()
    print("Stress set (synth.render_stress_case), corner error against exact truth, px: "
          "worst per-case median / worst corner")
    print(f"{'kind':14s} {'kit (detect_board_still)':>26s} {'ROS refinement':>22s}")
    for kind, r in st.items():
        cells = []
        for name in ("kit", "ros"):
            x = r[name]
            cells.append(f"{x['found']}/{x['cases']} found" if x["max_px"] is None else
                         f"{x['median_px_worst_case']:.3f} / {x['max_px']:.2f} ({x['found']}/{x['cases']})")
        print(f"{kind:14s} {cells[0]:>26s} {cells[1]:>22s}")


def print_real(real: dict) -> None:
    print()
    print("Real photographs (data/real, OpenCV samples, 9x6): calibrateCamera (k3 fixed) from each corner source")
    for side, rows in real.items():
        for name, r in rows.items():
            print(f"{side:6s} {name:26s} fx {r['fx']:7.1f} fy {r['fy']:7.1f} cx {r['cx']:6.1f} cy {r['cy']:6.1f} "
                  f"rms {r['rms']:.3f} px ({r['views']} views)")


def draw_figure(path: Path) -> None:
    """2x crops of the outer column: kit corners green, ROS / sample-pipeline corners red."""
    import cv2

    from dtscal_lib import synth
    from dtscal_lib.boards import parse_board
    from dtscal_lib.detect import detect_board_still

    tiles = []
    g = cv2.imread(str(REAL / "left" / "left02.jpg"), cv2.IMREAD_GRAYSCALE)
    board = parse_board("9x6", 0.03)
    kit, other = detect_board_still(g, board).corners, order_corners(_opencv_sample_corners(g), board)
    tiles.append(_crop(g, kit, other, board, "real left02: kit (green), OpenCV 11x11 (red)"))
    case = synth.render_stress_case("narrow_outer", 0)
    gs = cv2.cvtColor(case.image, cv2.COLOR_BGR2GRAY)
    kit, ros = detect_board_still(gs, case.board).corners, detect_board_ros(gs, case.board).corners
    tiles.append(_crop(gs, kit, ros, case.board, "stress: kit (green), ROS (red)"))
    w = max(t.shape[1] for t in tiles)
    tiles = [cv2.copyMakeBorder(t, 0, 8, 0, w - t.shape[1], cv2.BORDER_CONSTANT, value=(255, 255, 255)) for t in tiles]
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), np.vstack(tiles), [cv2.IMWRITE_PNG_COMPRESSION, 9])


def _crop(gray, kit, other, board, title: str, scale: int = 2):
    import cv2

    grid = kit.reshape(board.rows, board.cols, 2)
    # the outer column where the other corners are farthest from the kit's
    gap = np.linalg.norm(grid - np.asarray(other).reshape(grid.shape), axis=2) if other is not None else None
    col = grid[:, 0] if gap is None or gap[:, 0].max() >= gap[:, -1].max() else grid[:, -1]
    x0, y0 = np.floor(col.min(axis=0) - 50).astype(int)
    x1, y1 = np.ceil(col.max(axis=0) + 50).astype(int)
    x0, y0 = max(x0, 0), max(y0, 0)
    x1, y1 = min(x1, gray.shape[1]), min(y1, gray.shape[0])
    crop = cv2.resize(gray[y0:y1, x0:x1], None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
    img = cv2.cvtColor(crop, cv2.COLOR_GRAY2BGR)
    for pts, colour in ((other, (0, 0, 255)), (kit, (0, 200, 0))):
        if pts is None:
            continue
        for x, y in np.asarray(pts).reshape(-1, 2):
            c = (round((x - x0 + 0.5) * scale - 0.5), round((y - y0 + 0.5) * scale - 0.5))
            cv2.drawMarker(img, c, colour, cv2.MARKER_CROSS, 14, 2)
    bar = np.full((28, img.shape[1], 3), 255, np.uint8)
    cv2.putText(bar, title, (4, 19), cv2.FONT_HERSHEY_SIMPLEX, 0.38, (0, 0, 0), 1, cv2.LINE_AA)
    return np.vstack([bar, img])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", action="store_true", help="print the numbers as JSON")
    ap.add_argument("--check", action="store_true", help="exit 1 if the time target is missed")
    ap.add_argument("--quick", action="store_true", help="timing only, no quality set")
    ap.add_argument("--repeats", type=int, default=21, help="runs per timing (median)")
    ap.add_argument("--boards", type=int, default=60, help="board frames in the quality set")
    ap.add_argument("--empty", type=int, default=20, help="board-free frames in the quality set")
    ap.add_argument("--stress-seeds", type=int, default=3, help="seeds per stress kind")
    ap.add_argument("--figure", type=Path, help="write the real/stress corner figure to this PNG")
    args = ap.parse_args(argv)
    if args.figure is not None:
        draw_figure(args.figure)

    renderer = FrameRenderer()
    timing = part_timing(renderer, args.repeats)
    real_timing = part_real_timing(max(3, args.repeats // 3))
    quality = None if args.quick else part_quality(renderer, args.boards, args.empty)
    session = None if args.quick else part_session()
    stress = None if args.quick else part_stress(args.stress_seeds)
    real = None if args.quick else part_real()
    if args.json:
        print(json.dumps({"target_ms": TARGET_MS, "timing": timing, "real_timing": real_timing,
                          "quality": quality, "session": session,
                          "stress": stress, "real": real}, indent=2, default=float))
    else:
        print_report(timing, quality)
        print_real_timing(real_timing)
        if session is not None:
            print_session(session)
        if stress is not None:
            print_stress(stress)
        if real is not None:
            print_real(real)
    missed = [k for k, v in timing.items() if not v["meets_target"]]
    if not real_timing["meets_target"]:
        missed.append("real photographs (kit / OpenCV)")
    if args.check and missed:
        print(f"target missed for: {', '.join(missed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
