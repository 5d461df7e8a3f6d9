"""``dtscal grade``: the command-line front of the grader (registered in :mod:`dtscal_lib.cli`)."""

from __future__ import annotations

import sys

from .sandbox import CPU_S, MEM_MB, WALL_S, validate_limits


from .preflight import UNCONFINED  # the option that accepts grading without bubblewrap: it names the risk


def add_parser(sub) -> None:
    """Register ``grade`` on the ``dtscal`` sub-command parser."""
    sp = sub.add_parser("grade", help="grade submissions against the hidden cases (instructor)")
    sp.add_argument("submission", nargs="?",
                    help="a notebook, a .py file, a hand-in zip, one student's folder or a class folder (per "
                         "student: a folder of notebooks or hand-in zips, a zip, or a notebook)")
    sp.add_argument("--assignment", help="01_pinhole_projection ... 05_extrinsic_calibration (default: from the "
                                         "file name)")
    sp.add_argument("--json", metavar="FILE", help="write Gradescope's results.json (a class: one entry per student)")
    sp.add_argument("--csv", metavar="FILE", help="class summary: one row per student, one column per function")
    sp.add_argument("--report", metavar="DIR", help="write the class report page (score distribution per "
                                                    "function, most frequent mistakes) to DIR/index.html")
    sp.add_argument("--one-student", metavar="NAME",
                    help="grade everything under the folder (zips included) as one student's hand-in (what the "
                         "Gradescope bundle does with its submission folder)")
    sp.add_argument("--roster", metavar="CSV|DIR", help="grade students' git repositories: a CSV file "
                    "(student,repo[,commit]) or a folder of clones; each repository's workspace/ notebooks")
    sp.add_argument("--deadline", metavar="2026-12-01T23:59", help="with --roster: grade each repository's last "
                    "commit at or before this time (this machine's zone unless one is given)")
    sp.add_argument("--jobs", type=int, default=1, help="submissions graded in parallel (default 1)")
    sp.add_argument("--material", metavar="KIT", help="kit folder with grading/ and solutions/ (default: this kit)")
    sp.add_argument("--gradescope-bundle", metavar="OUT.zip", help="write the Gradescope autograder zip and exit")
    sp.add_argument("--wall", type=float, default=WALL_S, help=f"seconds per check (default {WALL_S:g})")
    sp.add_argument("--cpu", type=int, default=CPU_S, help=f"CPU seconds per check (default {CPU_S})")
    sp.add_argument("--mem", type=int, default=MEM_MB, help=f"memory per submission, MB (default {MEM_MB})")
    sp.add_argument(UNCONFINED, action="store_true", dest="unconfined",
                    help="grade even where bubblewrap cannot run: student code then reads (and writes) every file "
                         "this user can, the hidden cases and the other submissions included; without this "
                         "option `dtscal grade` refuses and says why bubblewrap fails here")
    sp.add_argument("-q", "--quiet", action="store_true", help="no table, no progress bar")
    sp.set_defaults(func=cmd_grade)
    add_nbgrader_option(sub)


def add_nbgrader_option(sub) -> None:
    """``dtscal release --nbgrader COURSE``: the export lives in the grading wing (it carries the hidden cases),
    so the grader adds the option to the teaching wing's ``release`` command (registered before it)."""
    rp = getattr(sub, "choices", {}).get("release")
    if rp is None:
        return
    rp.add_argument("--nbgrader", metavar="COURSE", help="write the course as an nbgrader course folder: "
                    "COURSE/source/<notebook>/<notebook>.ipynb (solution, read-only and autograded test "
                    "cells; the hidden cases in the tests' hidden part) and COURSE/nbgrader_config.py")
    release = rp.get_default("func")
    rp.set_defaults(func=lambda args: cmd_nbgrader(args) if getattr(args, "nbgrader", None) else release(args))


def cmd_nbgrader(args) -> int:
    from pathlib import Path

    from ..paths import repo_root
    from .nbgrader_export import export

    root = Path(args.repo) if args.repo else repo_root()
    for p in export(args.nbgrader, repo_root=root):
        print(p)
    print(f"nbgrader course in {args.nbgrader}: cd there, then `nbgrader generate_assignment 01_pinhole_projection`"
          " (one assignment per notebook); autograding needs the kit installed where nbgrader runs. nbgrader's "
          "autograde then warns \"Attribute 'checksum' for cell test_... has changed!\" for each test cell of each "
          "student: that is nbgrader putting back the hidden tests it stripped from the students' copy "
          "(jupyter/nbgrader#1961), not a student's tampering; a warning on any other cell is one",
          file=sys.stderr)
    return 0


def cmd_grade(args) -> int:
    from ..errors import DtscalError
    from .classroom import roster
    from .material import Material

    if args.gradescope_bundle:
        from .bundle import write_bundle

        out = write_bundle(args.gradescope_bundle, material_root=args.material, assignment=args.assignment,
                           unconfined=args.unconfined)
        print(f"wrote {out}: upload it as the autograder of a Gradescope programming assignment")
        return 0
    _check_outputs(args)  # a --csv that is a folder or a disk: refused before the class is graded
    git_notes: dict[str, list[str]] = {}
    if args.roster or args.deadline:  # git hand-in: clone each repository at its commit into a class folder
        import tempfile

        from .gitroster import checkout_roster, deadline_now_note, parse_deadline, read_roster, zone_given

        if not args.roster or args.submission:
            raise DtscalError("--deadline goes with --roster CSV|DIR; --roster replaces the submission argument")
        deadline = parse_deadline(args.deadline) if args.deadline else None
        entries = read_roster(args.roster)
        class_tmp = tempfile.TemporaryDirectory(prefix="dtscal-roster-class-")  # noqa: F841 (kept until graded)
        if deadline is not None and not args.quiet:
            print(f"grading {len(entries)} repositories at the "
                  f"{deadline_now_note(deadline, local=not zone_given(args.deadline))}", file=sys.stderr)
        for co in checkout_roster(entries, class_tmp.name, deadline=deadline):
            git_notes[co.student] = co.notes
        args.submission = class_tmp.name
    if not args.submission:
        raise DtscalError("give a submission (notebook, .py file or folder), or --gradescope-bundle OUT.zip")
    if not 1 <= args.jobs <= 64:
        raise DtscalError(f"--jobs {args.jobs}: give between 1 and 64 submissions graded in parallel")
    validate_limits(args.wall, args.cpu, args.mem)
    refuse_without_sandbox(args.unconfined)
    material = Material.load(args.material)
    from .preflight import check_numpy

    check_numpy()  # numpy that cannot load in the sandbox: refused here, not a class of "grader error"
    r = roster(args.submission, args.assignment, one_student=args.one_student)
    for student, notes in git_notes.items():  # which commit was graded, or why none: first in the row
        r.notes[student] = notes + r.notes.get(student, [])
    try:
        return _grade_roster(args, r, material)
    finally:
        r.cleanup()  # the members taken from hand-in zips


def _check_outputs(args) -> None:
    """Refuse, before any work, an output that cannot be written (:func:`dtscal_lib.safe_write.check`)."""
    from pathlib import Path

    from .. import safe_write

    for target, what in ((args.json, "--json file"), (args.csv, "--csv file"),
                         (args.report and Path(args.report) / "index.html", "class report (--report)")):
        if target:
            safe_write.check(target, what=what)


def _class_wide_notes(notes: dict[str, list[str]]) -> tuple[dict[str, list[str]], dict[str, list[str]]]:
    """The notes of each student less those on the course's notebooks without an exercise (06, 03b: the same for
    every student, said once for the class), and those: ``(row notes, {why: students})``. A student's own JSON
    (Gradescope's output) keeps them."""
    from .classroom import UNGRADED

    whys = [why for _prefix, _word, why in UNGRADED]
    rows: dict[str, list[str]] = {}
    per_class: dict[str, list[str]] = {}
    for student, said in notes.items():
        rows[student] = []
        for n in said:
            why = next((w for w in whys if n.endswith(f"not graded: {w}")), None)
            if why is None:
                rows[student].append(n)
            elif student not in per_class.setdefault(why, []):
                per_class[why].append(student)
    return rows, per_class


def refuse_without_sandbox(unconfined: bool) -> None:
    """Where bubblewrap cannot run, refuse to grade (with why and the fix, :mod:`.preflight`)
    unless the instructor accepted the risk with :data:`UNCONFINED`."""
    from ..errors import DtscalError
    from . import sandbox

    if sandbox.mode() == "bubblewrap" or unconfined:
        return
    from .preflight import diagnose, facts

    said = sandbox.bwrap_available()[1] if sandbox.MODE is None else "bubblewrap turned off (sandbox.MODE)"
    causes = "\n".join(f"  - {c.line()}" for c in diagnose(facts(), said))
    raise DtscalError("not grading: bubblewrap cannot run here, so student code would read and write every file "
                      f"this user can (the hidden cases, the other submissions).\n{causes}\nFix that (docs/ta.md, "
                      f"'Grading without bubblewrap'), or accept the risk with {UNCONFINED}.")


def _grade_roster(args, r, material) -> int:
    from .grade import not_handed_in
    from .classroom import grade_all
    from .report import grader_errors, gradescope, text, write_csv, write_json

    for n in r.unplaced:
        print(f"not graded: {n}", file=sys.stderr)
    row_notes, per_class = _class_wide_notes(r.notes)
    for why, students in per_class.items():  # once for the class, not once per student (nor per CSV row)
        print(f"not graded, for the whole class ({len(students)} student(s) handed it in): {why}", file=sys.stderr)
    for student in r.students:  # also in the CSV and JSON, next to the student's grades
        for n in row_notes.get(student, []):
            print(f"{student}: {n}", file=sys.stderr)
    from .sandbox import barriers

    held = barriers()  # which barriers hold around each submission on this machine (also in results.json)
    print(f"sandbox: {held['mode']}" + ("" if held["mode"] == "bubblewrap" else
                                        " -- NOT held: " + "; ".join(held["not_held"])), file=sys.stderr)
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
                                                for s, rs in sorted(by_student.items())},
                                   **({"not_graded": list(r.unplaced)} if r.unplaced else {}), "sandbox": held})
    if args.csv:
        write_csv(args.csv, by_student, row_notes)
    if args.report:
        from .classreport import write_report

        notes = dict(r.notes)
        if r.unplaced:
            notes["(class folder)"] = list(r.unplaced)
        page = write_report(args.report, by_student, notes)
        print(f"class report: {page}", file=sys.stderr)
    nothing = [s for s in r.students if not any(i.student == s for i in r.items)]
    if len(by_student) > 1 or nothing:
        print(f"graded {len(results)} notebook(s) of {len(by_student)} student(s), every student in the results"
              + (f"; nothing graded for {len(nothing)}: {', '.join(nothing[:10])}"
                 + (" ..." if len(nothing) > 10 else "") if nothing else "")
              + (f"; summary in {args.csv}" if args.csv else ""), file=sys.stderr)
    failed = grader_errors(by_student)
    if failed:
        print(f"not graded: grader error, rerun: {len(failed)} student(s) ({', '.join(failed[:10])}); their "
              "other grades stand. Rerun these students (a grader error is never the student's 0).", file=sys.stderr)
        return 3
    return 0
