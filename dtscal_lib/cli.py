"""The ``dtscal`` command.

Sub-commands::

    dtscal course                  open the course in JupyterLab (the student's workspace/; --instructor: solutions/)
    dtscal handin                  zip the student's workspace notebooks into handin/NAME.zip
    dtscal synth --out data        regenerate the synthetic recorded Duckiebot session
    dtscal calibrate-intrinsics    frames -> camera_intrinsic/<ROBOT>.yaml
    dtscal calibrate-extrinsics    one frame on the board -> camera_extrinsic/<ROBOT>.yaml
    dtscal handout OUT             write the student hand-out (alias: dtscal release OUT)
    dtscal release --check|--execute  check notebooks/ against solutions/ / re-run solutions, regenerate
    dtscal grade SUBMISSION        grade notebooks against the hidden cases (instructor)

Exit codes: 0 success, 1 a check failed, 2 bad input (the message says what to do), 3 a calibration
was computed but refused as implausible (nothing written over the robot's file; with --keep-anyway it
is kept as NAME.rejected.yaml beside it), 130 interrupted.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import warnings
from pathlib import Path

from .errors import CalibrationFileWarning, DtscalError, ImplausibleCalibrationError

#: camera.DIST_MODELS, written out so that the command starts without importing OpenCV (a test keeps them equal)
_MODELS = ("plumb_bob", "radial2", "rational_polynomial", "equidistant")
#: exit code of a calibration the kit refuses to believe (see dtscal_lib.plausibility)
EXIT_REFUSED = 3
#: library keyword spellings in messages -> the flags of this command
_FLAG_WORDING = {"topic=": "--topic", "keep_anyway=True": "--keep-anyway"}


def _board(args, charuco_ok: bool = True):
    from .validation import board_from_flags, charuco_from_flags

    if getattr(args, "charuco", None):
        if not charuco_ok:
            from .errors import DtscalError

            raise DtscalError("--charuco: the extrinsic calibration uses the printed chessboard on the ground "
                              "(Duckietown's A3 pattern, or the DD24's); drop --charuco and pass --board/--square")
        return charuco_from_flags(args.charuco, args.square, args.marker, args.aruco_dict, args.legacy)
    return board_from_flags(args.board, args.square)


def _cli_wording(message: str) -> str:
    """The library names its keyword arguments (``topic=``); on the command line they are flags."""
    for word, flag in _FLAG_WORDING.items():
        message = message.replace(word, flag)
    return message


def _report_doubts(run) -> int:
    """Exit code of a finished run: 0, or EXIT_REFUSED when the result was kept against the kit's doubts."""
    if not run.doubts:
        return 0
    print("dtscal: warning: the kit does not believe this calibration:", file=sys.stderr)
    for d in run.doubts:
        print(f"  - {d}", file=sys.stderr)
    where = f"kept as {run.path}" if run.path else "nothing written (--no-write)"  # written unless --no-write
    print(f"dtscal: --keep-anyway: {where}; the robot's own file is unchanged", file=sys.stderr)
    return EXIT_REFUSED


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


def _master(args) -> None:
    if args.master_uri:  # the live source and the commit both talk to this master
        os.environ["ROS_MASTER_URI"] = args.master_uri


def cmd_calibrate_intrinsics(args) -> int:
    from .pipeline import calibrate_intrinsics, parse_image_size

    _master(args)
    run = calibrate_intrinsics(args.source, board=_board(args), model=args.model, skew=args.skew,
                               robot=args.robot, out_dir=None if args.no_write else args.out, topic=args.topic,
                               progress=_progress(not args.quiet, "frames"), keep_anyway=args.keep_anyway,
                               max_seconds=args.max_seconds, image_size=parse_image_size(args.image_size))
    from .report import quality_for_run  # the session's verdict: warnings on stderr; figures + index.html with --report

    quality = quality_for_run(run, args.report)
    xval = _cross_validate(args, run)
    committed, failed = _commit(args, run, "intrinsics")
    if args.json:
        _print_json({**run.to_dict(), "quality": quality and quality.to_dict(), "cross_validation": xval,
                     "report": str(quality.report_path) if quality and quality.report_path else None,
                     "commit": committed, "commit_error": failed and str(failed)})
    else:
        r = run.result
        print(f"calibrated {run.robot}: {run.samples} samples from {run.tally.total} frames "
              f"({run.source}); rms {r.rms:.3f} px; verdict {quality.verdict if quality else 'none'}")
        names = ["fx", "fy", "cx", "cy"] + (["skew"] if r.skew else [])
        vals = [r.K[0, 0], r.K[1, 1], r.K[0, 2], r.K[1, 2]] + ([r.K[0, 1]] if r.skew else [])
        for n, v in zip(names, vals):
            print(f"  {n:5s} = {v:10.4f} +- {r.std.get(n, float('nan')):.4f}")
        print("  dist  = [" + ", ".join(f"{d:.6f}" for d in r.dist) + "]")
        if quality is not None:
            print("\n".join(quality.summary_lines(r.std_method)))  # sigma's method, what it means for a robot
        if xval is not None:
            print(f"  cross-validation ({len(xval['ratios'])} random half splits): half-set difference / "
                  "predicted sigma")
            for i, r in enumerate(xval["ratios"]):
                print(f"    split {i}: corners {r['corners']:.2f}, inside {r['inside']:.2f} (max {r['max_px']:.2f} px)")
            if xval["finding"]:
                print(f"  cross-validation: {xval['finding']['message']}; {xval['finding']['advice']}")
        if run.tally.rejected:
            print("  frames skipped: " + ", ".join(f"{k} {v}" for k, v in sorted(run.tally.rejected.items())))
        if run.path:
            print(f"wrote {run.path}")
        if quality is not None and quality.report_path:
            print(f"wrote {quality.report_path}")
        if committed:
            print(f"committed to {run.robot}: {committed}")
    if failed:  # after the result is printed: nothing computed is lost
        raise failed
    return _report_doubts(run)


def _cross_validate(args, run):
    """--cross-validate: the views' random halves against their predicted uncertainty (dtscal_lib.compare)."""
    if not args.cross_validate:
        return None
    from .compare import cross_validate

    r = run.result
    cv = cross_validate(r.object_points, r.image_points, r.image_size, model=r.model, skew=r.skew,
                        splits=args.cross_validate)
    finding = cv.finding()
    if finding is not None:
        print(f"dtscal: warning: {finding.warning()}", file=sys.stderr)
    return {**cv.to_dict(), "finding": finding.to_dict() if finding else None}


def _commit(args, run, kind: str):
    """--commit: send the result to the robot through its session; (reply, CommitError)."""
    from .robot import CommitError

    if not args.commit or run.doubts:  # a result the kit refused is never sent to the robot
        return None, None
    try:
        link = _dtps_link(args, run)
        if kind == "intrinsics":
            return run.session.commit(master_uri=args.master_uri, timeout=args.commit_timeout, dtps=link), None
        return run.session.commit(master_uri=args.master_uri, timeout=args.commit_timeout, url=args.upload_url,
                                  fmt=args.format, dtps=link), None
    except CommitError as exc:
        return None, exc


def _dtps_link(args, run):
    """Where --commit goes over DTPS: the ``dtps:`` source's robot, or the robot at --kvstore; else None (ROS)."""
    from .dtps_link import parse_dtps_spec

    if str(args.source).startswith("dtps:"):
        return parse_dtps_spec(args.source[5:], kvstore=args.kvstore)
    if args.kvstore:
        return parse_dtps_spec(run.robot, kvstore=args.kvstore)
    return None


def cmd_calibrate_extrinsics(args) -> int:
    from .pipeline import calibrate_extrinsics

    _master(args)
    run = calibrate_extrinsics(args.source, args.intrinsics, board=_board(args, charuco_ok=False), robot=args.robot,
                               out_dir=None if args.no_write else args.out, fmt=args.format,
                               topic=args.topic, progress=_progress(not args.quiet, "frames"),
                               keep_anyway=args.keep_anyway, max_seconds=args.max_seconds,
                               robot_type=args.robot_type)
    committed, failed = _commit(args, run, "extrinsics")
    if args.json:
        _print_json({**run.to_dict(), "commit": committed, "commit_error": failed and str(failed)})
    else:
        print(f"ground homography for {run.robot} from frame {run.frame_index} ({run.source}):")
        for row in run.H:
            print("  [" + ", ".join(f"{v: .8g}" for v in row) + "]")
        x, y = run.image_center_ground
        print(f"  image centre -> ground ({x:.3f}, {y:.3f}) m; corner residuals max "
              f"{run.residual_mm.max():.2f} mm")
        fr = run.frames()
        print(f"  frames: {fr['total']} read" + (f" of {fr['in_source']} (the first usable one is Duckietown's; "
              f"{fr['not_read']} not read)" if "in_source" in fr else "") + f", {fr['used']} used")
        if run.upside_down:
            from .ground import UPSIDE_DOWN_SAID

            print(f"  {UPSIDE_DOWN_SAID}")
        if run.camera_pose:
            print(f"  camera {run.camera_pose['height_m']:.3f} m above the ground, looking "
                  f"{run.camera_pose['pitch_down_deg']:.1f} degrees down")
        if run.path:
            print(f"wrote {run.path}")
        if committed:
            print(f"committed to {run.robot}: {committed}")
    if failed:  # after the result is printed: nothing computed is lost
        raise failed
    return _report_doubts(run)


def cmd_compare(args) -> int:
    """``dtscal compare A.yaml B.yaml``: mrcal's projection difference of B against A (dtscal_lib.compare)."""
    from .compare import PLACES, WITHIN_SIGMAS, projection_difference, write_figure

    # the paths, not their content: a file the kit wrote carries its uncertainty (dtscal_lib.file_uncertainty)
    comp = projection_difference(args.a, args.b, gridn_width=args.gridn, names=(str(args.a), str(args.b)))
    a, b = comp.cameras
    figure = None
    if args.report:
        out = Path(args.report)
        try:
            out.mkdir(parents=True, exist_ok=True)
            figure = out / "compare.png"
            write_figure(comp, figure)
        except OSError as e:
            raise DtscalError(f"--report {args.report}: cannot write the figure ({e}); "
                              "choose a writable folder") from None
    if args.json:
        _print_json({**comp.to_dict(), "figure": str(figure) if figure else None})
        return 0
    where = ("over the whole image weighted by 1/(sigma_A sigma_B)^2" if comp.focus_radius == float("inf")
             else f"within {comp.focus_radius:.0f} px of the centre")
    print(f"{args.b} against {args.a} ({a.model} / {b.model}, {a.size[0]}x{a.size[1]}): after a rotation of "
          f"{comp.rotation_deg:.3f} deg (fitted {where}, as mrcal does)")
    print(f"  max {comp.max_px:.3f} px, RMS {comp.rms_px:.3f} px over a {comp.diff.shape[1]}x{comp.diff.shape[0]} grid"
          + (f"; {comp.n_unprojectable} grid points cannot be unprojected by a model" if comp.n_unprojectable else ""))
    for name in PLACES:
        v = comp.at[name]
        print(f"  {name:12s} ({v['pixel'][0]:6.1f}, {v['pixel'][1]:6.1f}): {v['diff_px']:.3f} px")
    if comp.within is None:
        print("  not judged against their uncertainty: " + "; ".join(comp.unknown)
              + " (compare with the calibrations' own sigma in notebook 06 or with calibrate-intrinsics "
                "--cross-validate)")
    else:
        print(f"  {'within' if comp.within else 'NOT within'} their uncertainty: at most {comp.max_ratio:.2f} "
              f"times the combined 1-sigma sqrt(sigma_A^2 + sigma_B^2) (limit {WITHIN_SIGMAS:g})"
              + (f"; judged against one file's sigma only: {'; '.join(comp.unknown)}" if comp.unknown else ""))
    if figure:
        print(f"wrote {figure}")
    return 0


def cmd_synth(args) -> int:
    from .synth import generate, generate_charuco
    from .validation import check_output_folder, check_seed

    seed = check_seed(args.seed)
    out = check_output_folder(args.out)
    try:
        paths = generate_charuco(out, seed=seed) if args.charuco else generate(out, seed=seed, progress=not args.quiet)
    except OSError as e:
        raise DtscalError(f"--out {args.out}: writing the session failed ({e}); free space or choose another "
                          "folder") from None
    for p in (paths.values() if isinstance(paths, dict) else paths):
        print(p)
    return 0








def build_parser() -> argparse.ArgumentParser:
    from . import duckietown as dt  # the names in the help (numpy is imported by the commands anyway)

    p = argparse.ArgumentParser(prog="dtscal", description="Duckietown camera-calibration kit")
    sub = p.add_subparsers(dest="command", required=True)

    def board_args(sp):
        sp.add_argument("--board", default="7x5", help="inner corners CxR (default 7x5, the Duckietown board)")
        sp.add_argument("--square", type=float, default=0.031, help="square size in metres (default 0.031)")
        sp.add_argument("--charuco", metavar="SXxSY",
                        help="a ChArUco board of SX by SY squares (as printed and as ROS's calibrator takes it)"
                             " instead of a chessboard; partial views count. With --square, --marker")
        sp.add_argument("--marker", type=float, help="--charuco: side of one ArUco marker in metres")
        sp.add_argument("--aruco-dict", default="4x4_50", help="--charuco: the markers' dictionary, ROS's names "
                        "(aruco_orig, 4x4_50 ... 7x7_1000; default 4x4_50)")
        sp.add_argument("--legacy", action="store_true", help="--charuco: a board laid out as OpenCV <= 4.5 did "
                        "(calib.io's legacy switch; matters for an even number of rows)")

    def common(sp):
        sp.add_argument("--source", required=True,
                        help="ROS 1 or ROS 2 bag, video file, folder or glob of images; live: "
                        "dtps:ROBOT (its camera over DTPS, as duckietown-sdk; dtps:ROBOT@HOST:PORT), "
                        "ros:ROBOT (its camera topic via ROS_MASTER_URI), device:N (webcam), a stream URL")
        sp.add_argument("--topic", help=f"image topic in a bag (default: the one ending in {dt.IMAGE_SUFFIX})")
        sp.add_argument("--robot", help="robot name (default: from the bag topic "
                                        f"{dt.ros_name(dt.CAMERA_NODE, 'ROBOT')}/...)")
        sp.add_argument("--out", default="calibrations",
                        help="calibrations folder to write into (default ./calibrations)")
        sp.add_argument("--no-write", action="store_true", help="compute only, write no file")
        sp.add_argument("--json", action="store_true", help="print the result as one JSON object on stdout")
        sp.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
        sp.add_argument("--keep-anyway", action="store_true",
                        help="keep a result the kit finds implausible as NAME.rejected.yaml beside the robot's file "
                             "(exit code 3 still says it was refused)")
        board_args(sp)
        live = sp.add_argument_group("live camera and robot")
        live.add_argument("--max-seconds", type=float, default=300.0,
                          help="live sources: stop collecting after this long (default 300)")
        live.add_argument("--commit", action="store_true", help="also send the result to the robot (see README)")
        live.add_argument("--master-uri", help="the robot's ROS master (default $ROS_MASTER_URI)")
        live.add_argument("--kvstore", metavar="URL",
                          help="--commit over DTPS to this key-value store (default for a dtps:ROBOT source: "
                               f"http://ROBOT.local:{dt.KVSTORE_PORT}/); with a recording, commits to --robot "
                               "over DTPS")
        live.add_argument("--commit-timeout", type=float, default=10.0, help="seconds to wait for the robot")

    sp = sub.add_parser("calibrate-intrinsics", help="intrinsic calibration from a recording")
    common(sp)
    sp.add_argument("--model", choices=_MODELS, default="plumb_bob",
                    help="lens model: plumb_bob (k3 = 0, as ROS), radial2 (Zhang's k1, k2), rational_polynomial "
                         "(k1-k6, p1, p2) or equidistant (fisheye); the last two are calibrated by OpenCV")
    sp.add_argument("--skew", action="store_true", help="also estimate the skew of K (own refinement)")
    sp.add_argument("--image-size", metavar="WxH",
                    help="size of the frames to calibrate (default: the size in which the board is found most)")
    sp.add_argument("--report", metavar="DIR", help="write figures and DIR/index.html on how good the calibration is")
    sp.add_argument("--cross-validate", nargs="?", type=int, const=5, default=0, metavar="SPLITS",
                    help="calibrate random halves of the views (default 5 splits) and compare them against their "
                         "predicted uncertainty (plumb_bob and radial2)")
    sp.set_defaults(func=cmd_calibrate_intrinsics)

    sp = sub.add_parser("calibrate-extrinsics", help="ground homography from a frame of the robot on the board")
    common(sp)
    sp.add_argument("--intrinsics", required=True, help="Duckietown intrinsic YAML (camera_intrinsic/NAME.yaml)")
    sp.add_argument("--robot-type", choices=["duckiebot", "dd24"], default=None,
                    help="the robot on the board (default: the one the board implies: --square 0.017 is the DD24's)")
    sp.add_argument("--format", choices=["classic", "2"], default="classic",
                    help="extrinsic file: classic flat homography (default) or Duckietown's newer version 2")
    sp.add_argument("--upload-url", help="--commit: where to POST the extrinsic file (default " + dt.ROBOT_FILES_URL
                    .format(host="ROBOT.local", kind="camera_extrinsic", robot="ROBOT") + ")")
    sp.set_defaults(func=cmd_calibrate_extrinsics)

    sp = sub.add_parser("compare", help="how far two intrinsic calibrations of one camera differ over the image")
    sp.add_argument("a", help="intrinsic file (camera_intrinsic/NAME.yaml), e.g. the robot's current one")
    sp.add_argument("b", help="intrinsic file to compare with it, e.g. the new calibration")
    sp.add_argument("--gridn", type=int, default=60, help="grid points across the image (default 60, as mrcal)")
    sp.add_argument("--json", action="store_true", help="print the result as one JSON object on stdout")
    sp.add_argument("--report", metavar="DIR", help="write the difference map DIR/compare.png")
    sp.set_defaults(func=cmd_compare)

    sp = sub.add_parser("synth", help="regenerate the synthetic recorded Duckiebot session")
    sp.add_argument("--out", default="data", help="data folder (default ./data)")
    sp.add_argument("--seed", type=int, default=None, help="random seed (default: the one the shipped data used)")
    sp.add_argument("--charuco", action="store_true", help="the ChArUco sweep instead (session/charuco.bag)")
    sp.add_argument("-q", "--quiet", action="store_true")
    sp.set_defaults(func=cmd_synth)

    from .teaching.command import add_parsers as add_teaching_parsers  # course, handin, release, handout

    add_teaching_parsers(sub)

    try:
        from .grading.command import add_parser as add_grade_parser  # `dtscal grade` (the autograder)
    except ModuleNotFoundError:  # the student hand-out ships without the grader
        sp = sub.add_parser("grade", help="grading is part of the instructor's kit, not of this hand-out")
        sp.add_argument("args", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)  # whatever the kit's takes
        sp.set_defaults(func=_no_grader)
    else:
        add_grade_parser(sub)
    return p


def _no_grader(args) -> int:
    print("dtscal: error: this course is a student hand-out, which has no autograder; your instructor grades "
          "with the instructor's kit. To check your work, run the self-checks in your notebooks.", file=sys.stderr)
    return 2




def _print_warning(message, category, filename, lineno, file=None, line=None) -> None:
    if issubclass(category, CalibrationFileWarning):
        print(f"dtscal: warning: {message}", file=sys.stderr)
    else:
        print(warnings.formatwarning(message, category, filename, lineno, line), end="", file=sys.stderr)


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        with warnings.catch_warnings():  # a file read as Duckietown reads it, with a remark: one line, no traceback
            warnings.simplefilter("always", CalibrationFileWarning)
            warnings.showwarning = _print_warning
            return int(args.func(args) or 0)
    except ImplausibleCalibrationError as exc:
        print(f"dtscal: error: {_cli_wording(str(exc))}", file=sys.stderr)
        return EXIT_REFUSED
    except DtscalError as exc:
        print(f"dtscal: error: {_cli_wording(str(exc))}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("dtscal: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `dtscal ... --json | head`: the reader left; not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
