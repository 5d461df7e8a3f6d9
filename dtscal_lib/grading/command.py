"""``dtscal grade``: the command-line front of the grader (registered in :mod:`dtscal_lib.cli`)."""

from __future__ import annotations

import sys

from .sandbox import CPU_S, MEM_MB, WALL_S, validate_limits


def add_parser(sub) -> None:
    """Register ``grade`` on the ``dtscal`` sub-command parser."""
    sp = sub.add_parser("grade", help="grade submissions against the hidden cases (instructor)")
    sp.add_argument("submission", nargs="?",
                    help="a notebook, a .py file, one student's folder or a class folder (one entry per student)")
    sp.add_argument("--assignment", help="01_pinhole_projection ... 05_extrinsic_calibration (default: from the "
                                         "file name)")
    sp.add_argument("--json", metavar="FILE", help="write Gradescope's results.json (a class: one entry per student)")
    sp.add_argument("--csv", metavar="FILE", help="class summary: one row per student, one column per function")
    sp.add_argument("--report", metavar="DIR", help="write the class report page (score distribution per "
                                                    "function, most frequent mistakes) to DIR/index.html")
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
    from .classroom import grade_all, roster
    from .grade import not_handed_in
    from .material import Material
    from .report import gradescope, text, write_csv, write_json

    if args.gradescope_bundle:
        from .bundle import write_bundle

        out = write_bundle(args.gradescope_bundle, material_root=args.material, assignment=args.assignment)
        print(f"wrote {out}: upload it as the autograder of a Gradescope programming assignment")
        return 0
    if not args.submission:
        raise DtscalError("give a submission (notebook, .py file or folder), or --gradescope-bundle OUT.zip")
    if not 1 <= args.jobs <= 64:
        raise DtscalError(f"--jobs {args.jobs}: give between 1 and 64 submissions graded in parallel")
    validate_limits(args.wall, args.cpu, args.mem)
    import tempfile

    from .bundle import unpack_zip_submission

    material = Material.load(args.material)
    unpacked = tempfile.TemporaryDirectory(prefix="dtscal-handin-")  # a hand-in zip (`dtscal handin`)
    r = roster(unpack_zip_submission(args.submission, unpacked.name), args.assignment)
    for student in r.students:  # also in the CSV and JSON, next to the student's grades
        for n in r.notes.get(student, []):
            print(f"{student}: {n}", file=sys.stderr)
    from .sandbox import GRADER_ERROR, barriers

    held = barriers()  # which barriers hold around each submission on this machine (also in results.json)
    print(f"sandbox: {held['mode']}" + ("" if held["mode"] == "bubblewrap" else f" -- {held['filesystem']}"),
          file=sys.stderr)
    results = grade_all(r.items, material, jobs=args.jobs, progress=not args.quiet,
                        wall_s=args.wall, cpu_s=args.cpu, mem_mb=args.mem)
    by_student = {s: [] for s in r.students}
    for item, res in zip(r.items, results):
        by_student[item.student].append(res)
    for s, rs in by_student.items():  # the same columns and maximum for every student
        have = {x.assignment for x in rs}
        rs.extend(not_handed_in(a, material, s) for a in r.assignments if a not in have)
        rs.sort(key=lambda x: x.assignment)
    if not args.quiet:
        for res in results:
            print(text(res))
            print()
    if args.json:
        if len(by_student) == 1:
            s = next(iter(by_student))
            write_json(args.json, {**gradescope(by_student[s], r.notes.get(s, [])), "sandbox": held})
        else:
            write_json(args.json, {"students": {s: gradescope(rs, r.notes.get(s, []))
                                                for s, rs in sorted(by_student.items())}, "sandbox": held})
    if args.csv:
        write_csv(args.csv, by_student, r.notes)
    if args.report:
        from .classreport import write_report

        page = write_report(args.report, by_student, r.notes)
        print(f"class report: {page}", file=sys.stderr)
    if len(by_student) > 1:
        print(f"graded {len(results)} submission(s) of {len(by_student)} student(s)"
              + (f"; summary in {args.csv}" if args.csv else ""), file=sys.stderr)
    failed = [f"{x.student} {x.assignment}" for x in results if any(n.startswith(GRADER_ERROR) for n in x.notes)]
    if failed:  # never a silent zero: the instructor reruns these
        print(f"{GRADER_ERROR}: {len(failed)} submission(s) could not be graded: {', '.join(failed[:20])}",
              file=sys.stderr)
        return 3
    return 0
