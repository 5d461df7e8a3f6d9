"""The ``dtscal`` command.

Sub-commands::

    dtscal course                  open the course in JupyterLab (notebooks/ on the bundled session)
    dtscal synth --out data        regenerate the synthetic recorded Duckiebot session
    dtscal calibrate-intrinsics    frames -> camera_intrinsic/<ROBOT>.yaml
    dtscal calibrate-extrinsics    one frame on the board -> camera_extrinsic/<ROBOT>.yaml
    dtscal release OUT | --check   write the student version of the course / check notebooks/
    dtscal grade SUBMISSION        grade notebooks against the hidden cases (instructor)

Exit codes: 0 success, 1 a check failed, 2 bad input (the message says what to do).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from .errors import DtscalError


def _board(args):
    from .boards import parse_board

    return parse_board(args.board, args.square)


def _progress(enabled: bool, desc: str):
    if not enabled:
        return None
    from tqdm import tqdm

    def wrap(src):
        try:
            total = len(src)
        except TypeError:
            total = None
        # on stderr, so that --json output on stdout stays one clean object; -q turns it off
        return tqdm(src, total=total, desc=desc, unit="frame", file=sys.stderr, leave=False, mininterval=0.5)

    return wrap


def _print_json(obj) -> None:
    json.dump(obj, sys.stdout, indent=None, sort_keys=False)
    sys.stdout.write("\n")


def cmd_calibrate_intrinsics(args) -> int:
    from .pipeline import calibrate_intrinsics

    run = calibrate_intrinsics(args.source, board=_board(args), model=args.model, skew=args.skew,
                               robot=args.robot, out_dir=None if args.no_write else args.out, topic=args.topic,
                               progress=_progress(not args.quiet, "frames"))
    if args.json:
        _print_json(run.to_dict())
    else:
        r = run.result
        print(f"calibrated {run.robot}: {run.samples} samples from {run.tally.total} frames "
              f"({run.source}); rms {r.rms:.3f} px")
        names = ["fx", "fy", "cx", "cy"] + (["skew"] if r.skew else [])
        vals = [r.K[0, 0], r.K[1, 1], r.K[0, 2], r.K[1, 2]] + ([r.K[0, 1]] if r.skew else [])
        for n, v in zip(names, vals):
            print(f"  {n:5s} = {v:10.4f} +- {r.std.get(n, float('nan')):.4f}")
        print("  dist  = [" + ", ".join(f"{d:.6f}" for d in r.dist) + "]")
        if run.tally.rejected:
            print("  frames skipped: " + ", ".join(f"{k} {v}" for k, v in sorted(run.tally.rejected.items())))
        if run.path:
            print(f"wrote {run.path}")
    return 0


def cmd_calibrate_extrinsics(args) -> int:
    from .pipeline import calibrate_extrinsics

    run = calibrate_extrinsics(args.source, args.intrinsics, board=_board(args), robot=args.robot,
                               out_dir=None if args.no_write else args.out, topic=args.topic,
                               progress=_progress(not args.quiet, "frames"))
    if args.json:
        _print_json(run.to_dict())
    else:
        print(f"ground homography for {run.robot} from frame {run.frame_index} ({run.source}):")
        for row in run.H:
            print("  [" + ", ".join(f"{v: .8g}" for v in row) + "]")
        x, y = run.image_center_ground
        print(f"  image centre -> ground ({x:.3f}, {y:.3f}) m; corner residuals max "
              f"{run.residual_mm.max():.2f} mm")
        if run.path:
            print(f"wrote {run.path}")
    return 0


def cmd_synth(args) -> int:
    from .synth import generate

    paths = generate(Path(args.out), seed=args.seed, progress=not args.quiet)
    for p in (paths.values() if isinstance(paths, dict) else paths):
        print(p)
    return 0


def cmd_release(args) -> int:
    from . import release
    from .paths import repo_root

    root = Path(args.repo) if args.repo else repo_root()
    if args.check:
        diffs = release.check_notebooks(root / "solutions", root / "notebooks")
        if diffs:
            print("notebooks/ is out of date with solutions/; run `dtscal release --write` to regenerate:",
                  file=sys.stderr)
            for d in diffs:
                print("  " + d, file=sys.stderr)
            return 1
        print("notebooks/ matches solutions/")
        return 0
    if args.execute:
        for p in release.execute_solutions(root / "solutions"):
            print(f"executed {p}")
    if args.write or args.execute:
        for p in release.generate_notebooks(root / "solutions", root / "notebooks"):
            print(p)
        return 0
    if not args.out:
        raise DtscalError("give OUT (folder for the student release), or --check, or --write")
    print(release.release(Path(args.out), repo_root=root))
    return 0


def cmd_course(args) -> int:
    from .datasets import session_dir
    from .paths import repo_root

    root = repo_root()
    session_dir()  # fails early, with the fix, if the recording is missing
    cmd = [sys.executable, "-m", "jupyterlab", f"--ServerApp.root_dir={root}", f"--port={args.port}"]
    if args.no_browser:
        cmd.append("--no-browser")
    if args.ip:
        cmd.append(f"--ip={args.ip}")
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        cmd.append("--allow-root")  # containers and course VMs often run as root
    notebook = root / "notebooks" / "01_pinhole_projection.ipynb"
    if notebook.exists():
        cmd.append(str(notebook))
    print("starting JupyterLab:", " ".join(cmd), file=sys.stderr)
    os.execv(sys.executable, cmd)
    return 0  # pragma: no cover


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="dtscal", description="Duckietown camera-calibration kit")
    sub = p.add_subparsers(dest="command", required=True)

    def board_args(sp):
        sp.add_argument("--board", default="7x5", help="inner corners CxR (default 7x5, the Duckietown board)")
        sp.add_argument("--square", type=float, default=0.031, help="square size in metres (default 0.031)")

    def common(sp):
        sp.add_argument("--source", required=True, help="ROS 1 bag, video file, folder or glob of images")
        sp.add_argument("--topic", help="image topic in a bag (default: the one ending in /image/compressed)")
        sp.add_argument("--robot", help="robot name (default: from the bag topic /ROBOT/camera_node/...)")
        sp.add_argument("--out", default="calibrations", help="calibrations folder to write into (default ./calibrations)")
        sp.add_argument("--no-write", action="store_true", help="compute only, write no file")
        sp.add_argument("--json", action="store_true", help="print the result as one JSON object on stdout")
        sp.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
        board_args(sp)

    sp = sub.add_parser("calibrate-intrinsics", help="intrinsic calibration from a recording")
    common(sp)
    sp.add_argument("--model", choices=["plumb_bob", "radial2"], default="plumb_bob")
    sp.add_argument("--skew", action="store_true", help="also estimate the skew of K (own refinement)")
    sp.set_defaults(func=cmd_calibrate_intrinsics)

    sp = sub.add_parser("calibrate-extrinsics", help="ground homography from a frame of the robot on the board")
    common(sp)
    sp.add_argument("--intrinsics", required=True, help="Duckietown intrinsic YAML (camera_intrinsic/NAME.yaml)")
    sp.set_defaults(func=cmd_calibrate_extrinsics)

    sp = sub.add_parser("synth", help="regenerate the synthetic recorded Duckiebot session")
    sp.add_argument("--out", default="data", help="data folder (default ./data)")
    sp.add_argument("--seed", type=int, default=None, help="random seed (default: the one the shipped data used)")
    sp.add_argument("-q", "--quiet", action="store_true")
    sp.set_defaults(func=cmd_synth)

    sp = sub.add_parser("release", help="student version of the course; --check compares notebooks/ with solutions/")
    sp.add_argument("out", nargs="?", help="folder to write the student release into")
    sp.add_argument("--check", action="store_true", help="exit 1 if notebooks/ differs from what would be generated")
    sp.add_argument("--write", action="store_true", help="regenerate notebooks/ from solutions/")
    sp.add_argument("--execute", action="store_true",
                    help="re-run every solution notebook (storing its outputs), then regenerate notebooks/")
    sp.add_argument("--repo", help="kit checkout (default: the one this package runs from)")
    sp.set_defaults(func=cmd_release)

    sp = sub.add_parser("course", help="open the course in JupyterLab")
    sp.add_argument("--port", type=int, default=8888)
    sp.add_argument("--ip", default=None)
    sp.add_argument("--no-browser", action="store_true")
    sp.set_defaults(func=cmd_course)

    from .grading.command import add_parser as add_grade_parser  # `dtscal grade` (the autograder)

    add_grade_parser(sub)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except DtscalError as exc:
        print(f"dtscal: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("dtscal: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `dtscal ... --json | head`: the reader left; not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
