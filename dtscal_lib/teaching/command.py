"""``dtscal course``, ``handin``, ``release`` and ``handout``: the teaching layer's commands.

Registered on the ``dtscal`` parser by :mod:`dtscal_lib.cli`, as :mod:`dtscal_lib.grading.command` registers
``grade`` (and ``release --nbgrader``, the nbgrader export, which holds the hidden cases); the calibration
commands stay in ``cli.py``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from ..errors import DtscalError


def add_parsers(sub) -> None:
    """Register ``handout``, ``release``, ``course`` and ``handin`` on the ``dtscal`` sub-command parser."""
    for name in ("handout", "release"):
        sp = sub.add_parser(name, help="write the student hand-out into OUT; --check compares notebooks/ "
                                       "with solutions/")
        release_args(sp)

    sp = sub.add_parser("course",
                        help="open the course in JupyterLab (a student's workspace; --instructor: solutions/)")
    sp.add_argument("--port", type=int, default=8888)
    sp.add_argument("--ip", default=None)
    sp.add_argument("--no-browser", action="store_true")
    sp.add_argument("--instructor", action="store_true", help="open solutions/ (the instructor's kit) instead")
    sp.add_argument("--update", action="store_true",
                    help="carry your code into the current notebooks/ (old notebooks kept in workspace/backups/), "
                         "then open the course")
    sp.add_argument("--no-open", action="store_true",
                    help="prepare the workspace (and --update it) but do not start JupyterLab")
    sp.set_defaults(func=cmd_course)

    sp = sub.add_parser("handin", help="zip your workspace notebooks into handin/NAME.zip to hand in")
    sp.add_argument("--name", help="your name, for the file name (asked the first time and remembered in "
                    "handin/.name; giving it again changes it and replaces the zip)")
    sp.add_argument("--out", metavar="FILE.zip", help="where to write the zip (default handin/NAME.zip)")
    sp.set_defaults(func=cmd_handin)


def cmd_release(args) -> int:
    from ..paths import repo_root
    from . import release

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
        for p in release.execute_solutions(root / "solutions", progress=True):
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
    from ..datasets import session_dir
    from ..paths import repo_root
    from . import workspace

    root = repo_root()
    if not args.no_open:  # from here to JupyterLab serving can take 20 s on a loaded machine: never quiet
        print("dtscal course: opening the course (a line every few seconds until JupyterLab serves)",
              file=sys.stderr, flush=True)
        _say_while_jupyterlab_starts()
    if args.update:
        report = workspace.update_workspace(root)
        print(report.text(), flush=True)
        if not report.ok:
            print("the course was not opened: fix what the update says above, then run the update again",
                  file=sys.stderr)
            return 1
    if args.no_open:
        if not args.instructor:
            workspace.ensure_workspace(root)
        print("the course is ready; open it with `bash start.sh` (in a checkout: `dtscal course`)", file=sys.stderr)
        return 0
    session_dir()  # fails early, with the fix, if the recording is missing
    cmd = workspace.jupyter_command(root, instructor=args.instructor, port=args.port, ip=args.ip,
                                    no_browser=args.no_browser)
    print("starting JupyterLab:", " ".join(cmd), file=sys.stderr, flush=True)
    os.execv(sys.executable, cmd)
    return 0  # pragma: no cover


#: seconds between two "JupyterLab is starting" lines (start.sh's and course.sh's installer lines come every 5 s too)
TICK_SECONDS = 5.0


def _say_while_jupyterlab_starts(limit: float = 600.0) -> None:
    """Fork a helper that says every few seconds that the course is opening, until JupyterLab serves.

    Forked first thing (before the workspace is made or updated), since this process then becomes JupyterLab
    (``os.execv`` keeps the pid), which writes ``jpserver-<pid>.json`` in Jupyter's runtime folder once it serves
    (jupyter_server's ``ServerApp.info_file``): the helper stops there, or when the process is gone (an update that
    failed, JupyterLab stopped), or after ``limit`` seconds. At load 10 on 2 cores the workspace took 8 s and
    JupyterLab 10 s or more before its first line (benchmarks/bench_start.py): silences, without the helper.
    The helper is forked twice, so that it is nobody's zombie when it ends.
    ``DTSCAL_TICK_SECONDS`` changes the interval.
    """
    import time

    from jupyter_core.paths import jupyter_runtime_dir

    every = float(os.environ.get("DTSCAL_TICK_SECONDS", TICK_SECONDS))
    me = os.getpid()
    info = Path(jupyter_runtime_dir()) / f"jpserver-{me}.json"
    try:
        first = os.fork()
        if first:
            os.waitpid(first, 0)  # the helper's parent exits at once: the helper is nobody's zombie
            return
    except OSError:
        return  # no helper: JupyterLab starts all the same
    try:
        if os.fork():
            os._exit(0)
        t0 = time.monotonic()
        said = 0
        while time.monotonic() - t0 < limit:
            time.sleep(min(0.5, every))
            try:
                os.kill(me, 0)  # JupyterLab is still there
            except ProcessLookupError:
                break
            if info.exists():
                break
            n = int((time.monotonic() - t0) // every)
            if n > said:
                said = n
                print(f"dtscal course: ... opening the course, JupyterLab is starting ({n * every:g} s)",
                      file=sys.stderr, flush=True)
    finally:
        os._exit(0)


def cmd_handin(args) -> int:
    from ..paths import repo_root
    from . import handin

    ask = input if sys.stdin is not None and sys.stdin.isatty() else None  # asked once, then remembered
    path, names = handin.write_handin(repo_root(), name=args.name, out=args.out, ask=ask)
    print(f"wrote {path} with {len(names)} notebook(s): {', '.join(names)}")
    print(f"hand in this file as it is (upload it to Gradescope, or as your instructor says). It is named "
          f"{path.stem}; to change the name: --name \"Your Name\" (the old zip is replaced).")
    print(f"If your course collects git repositories instead: {handin.GIT_HANDIN}")
    return 0


def release_args(sp) -> None:
    sp.add_argument("out", nargs="?", help="folder to write the student release into")
    sp.add_argument("--check", action="store_true", help="exit 1 if notebooks/ differs from what would be generated")
    sp.add_argument("--write", action="store_true", help="regenerate notebooks/ from solutions/ (seconds; enough "
                    "after a change to text or code that leaves the stored outputs as they are)")
    sp.add_argument("--execute", action="store_true",
                    help="re-run every solution notebook (storing its outputs), then regenerate notebooks/")
    sp.add_argument("--repo", help="kit checkout (default: the one this package runs from)")
    sp.set_defaults(func=cmd_release)
