"""The README is the kit's front door: at most 250 lines, the three paths in the first screen after the
two commands, and every file, command and flag it names exists.

Lines holding a ``[placeholder: ...]`` (sections still to be written) are not checked for names.
"""

from __future__ import annotations

import contextlib
import io
import re
import shlex
from pathlib import Path

import pytest

from dtscal_lib.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
#: a terminal's first screen
SCREEN = 50
#: folders the kit makes at run time (not in a checkout): a student's workspace, a calibrations folder, ...
MADE_AT_RUN_TIME = ("workspace/", "calibrations/", "class/", "OUT", "DIR/", "autograder.zip", "grades.csv",
                    "results.json", "start.sh", "handin/")


def lines() -> list[str]:
    return README.read_text(encoding="utf-8").splitlines()


def checked_text() -> str:
    return "\n".join(line for line in lines() if "[placeholder" not in line)


def test_at_most_250_lines():
    assert len(lines()) <= 250


def test_the_three_paths_come_in_the_first_screen_after_the_two_commands():
    text = lines()
    commands = next(i for i, line in enumerate(text) if line.startswith("bash scripts/test.sh"))
    assert any(line.startswith("bash scripts/course.sh") for line in text[:commands])
    first_screen = "\n".join(text[commands: commands + SCREEN])
    for path in ("**Student.**", "**Instructor.**", "**Robot (TA).**"):
        assert path in first_screen, path


def _names() -> set[str]:
    text = checked_text()
    names = set(re.findall(r"`([^`\n]+)`", text)) | set(re.findall(r"\]\(([^)\s]+)\)", text))
    out = set()
    for name in names:
        for word in name.split():
            path_like = "/" in word or re.search(r"\.(py|md|sh|ipynb|bag|toml)$", word)
            if len(word) > 1 and re.fullmatch(r"[\w./-]+", word) and path_like:
                out.add(word)
    return out


def _exists(name: str) -> bool:
    if name.startswith(("http://", "https://", ".venv/")) or "ROBOT" in name or name.startswith(MADE_AT_RUN_TIME):
        return True
    candidates = [ROOT / name, ROOT / "dtscal_lib" / name]
    candidates += list((ROOT / "dtscal_lib").glob(f"*/{name}"))
    return any(p.exists() for p in candidates)


def test_every_file_it_names_exists():
    names = _names()
    assert len(names) > 20  # the check reads the names at all
    assert sorted(n for n in names if not _exists(n)) == []


def test_every_notebook_it_names_exists():
    for nb in set(re.findall(r"`(0\d_[a-z_]+)`", checked_text())):
        assert (ROOT / "solutions" / f"{nb}.ipynb").exists(), nb
        assert (ROOT / "notebooks" / f"{nb}.ipynb").exists(), nb


def _command_lines() -> list[str]:
    blocks = re.findall(r"```bash\n(.*?)```", checked_text(), flags=re.S)
    joined = "\n".join(blocks).replace("\\\n", " ")
    return [line.split("#")[0].strip() for line in joined.splitlines() if line.split("#")[0].strip()]


def test_every_command_parses():
    """Each ``dtscal`` line parses with the real parser; each script and benchmark exists with its flags."""
    parser = build_parser()
    seen = 0
    for line in _command_lines():
        words = shlex.split(line)
        if words[0] == "export":
            continue
        if words[0].endswith("dtscal"):
            parser.parse_args(words[1:])  # exits (SystemExit) on an unknown sub-command or flag
        elif words[0] == "bash":
            assert (ROOT / words[1]).exists(), line
        elif words[0].endswith("python"):
            script = ROOT / words[1]
            source = script.read_text(encoding="utf-8")
            for flag in (w for w in words[2:] if w.startswith("--")):
                assert flag in source, (line, flag)
        else:
            pytest.fail(f"a command the test does not know: {line}")
        seen += 1
    assert seen >= 15


def _help(words: list[str]) -> str:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit):
        build_parser().parse_args([*words, "--help"])
    return out.getvalue()


def test_every_flag_it_names_exists():
    commands = re.findall(r"\{([a-z,-]+)\}", _help([]))[0].split(",")
    flags = set()
    for command in commands:
        flags.update(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]+)", _help([command])))
    named = set(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]+)", checked_text()))
    named -= {f for line in _command_lines() if "python" in line.split()[0] for f in line.split()}
    # the hand-out's start.sh takes a few flags of its own (--update, --handin)
    from dtscal_lib.teaching.release import START_SH
    flags |= {f for f in re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]+)", START_SH)}
    assert len(flags) > 20 and sorted(named - flags) == []
