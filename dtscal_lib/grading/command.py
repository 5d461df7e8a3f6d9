"""``dtscal grade``: the command-line front of the grader (registered in :mod:`dtscal_lib.cli`)."""

from __future__ import annotations

import sys
from collections import defaultdict

from .sandbox import CPU_S, MEM_MB, WALL_S


def add_parser(sub) -> None:
    """Register ``grade`` on the ``dtscal`` sub-command parser."""
    sp = sub.add_parser("grade", help="grade submissions against the hidden cases (instructor)")
    sp.add_argument("submission", nargs="?",
                    help="a notebook, a .py file, one student's folder or a class folder (one entry per student)")
    sp.add_argument("--assignment", help="01_pinhole_projection ... 05_extrinsic_calibration (default: from the "
                                         "file name)")
    sp.add_argument("--json", metavar="FILE", help="write Gradescope's results.json (a class: one entry per student)")
    sp.add_argument("--csv", metavar="FILE", help="class summary: one row per student, one column per function")
    sp.add_argument("--jobs", type=int, default=1, help="submissions graded in parallel (default 1)")
    sp.add_argument("--material", metavar="KIT", help="kit folder with grading/ and solutions/ (default: this kit)")
    sp.add_argument("--gradescope-bundle", metavar="OUT.zip", help="write the Gradescope autograder zip and exit")
    sp.add_argument("--wall", type=float, default=WALL_S, help=f"seconds per check (default {WALL_S:g})")
    sp.add_argument("--cpu", type=int, default=CPU_S, help=f"CPU seconds per check (default {CPU_S})")
    sp.add_argument("--mem", type=int, default=MEM_MB, help=f"memory per submission, MB (default {MEM_MB})")
    sp.add_argument("-q", "--quiet", action="store_true", help="no table, no progress bar")
    sp.set_defaults(func=cmd_grade)


def cmd_grade(args) -> int:
    from ..errors import DtscalError
    from .classroom import discover, grade_all
    from .material import Material
    from .report import gradescope, text, write_csv, write_json

    if args.gradescope_bundle:
        from .bundle import write_bundle

        out = write_bundle(args.gradescope_bundle, material_root=args.material, assignment=args.assignment)
        print(f"wrote {out}: upload it as the autograder of a Gradescope programming assignment")
        return 0
    if not args.submission:
        raise DtscalError("give a submission (notebook, .py file or folder), or --gradescope-bundle OUT.zip")
    if args.jobs < 1:
        raise DtscalError("--jobs must be at least 1")
    import tempfile

    from .bundle import unpack_zip_submission

    material = Material.load(args.material)
    unpacked = tempfile.TemporaryDirectory(prefix="dtscal-handin-")  # a hand-in zip (`dtscal handin`)
    submission = unpack_zip_submission(args.submission, unpacked.name)
    items, skipped = discover(submission, args.assignment)
    for s in skipped:
        print(f"skipped {s}", file=sys.stderr)
    results = grade_all(items, material, jobs=args.jobs, progress=not args.quiet,
                        wall_s=args.wall, cpu_s=args.cpu, mem_mb=args.mem)
    by_student = defaultdict(list)
    for r in results:
        by_student[r.student].append(r)
    if not args.quiet:
        for r in results:
            print(text(r))
            print()
    if args.json:
        if len(by_student) == 1:
            write_json(args.json, gradescope(next(iter(by_student.values()))))
        else:
            write_json(args.json, {"students": {s: gradescope(rs) for s, rs in sorted(by_student.items())}})
    if args.csv:
        write_csv(args.csv, by_student)
    if len(by_student) > 1:
        print(f"graded {len(results)} submission(s) of {len(by_student)} student(s)"
              + (f"; summary in {args.csv}" if args.csv else ""), file=sys.stderr)
    return 0
