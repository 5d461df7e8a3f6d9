"""One hand-in story in every text the kit ships, and no retired service in any (issue 32).

The texts: the kit's README and docs, the hand-out's README, start.sh, its help and the scripts it carries, the TA page
as the hand-out carries it, every notebook (solutions and student versions), and the library's source (its
docstrings and every message it prints, `dtscal handin`'s included). Read from the files and from the strings
release.py writes into the hand-out, independently of how release.py assembles them.
"""

from __future__ import annotations

import json
import re

import pytest

from dtscal_lib.teaching import release as rel
from dtscal_lib.teaching.handin import GIT_HANDIN
from nbtools import ROOT

#: services a course used and that are gone; a text may name one only in a sentence that says it is retired
#: (a TA who used it learns what replaced it), never as a way to hand in
RETIRED = {
    # GitHub Classroom: retired by GitHub in 2026 (issue 32; the date the kit's docs give, 2026-08-28, is in
    # dtscal_lib/grading/gitroster.py's docstring)
    "GitHub Classroom": re.compile(r"github\s+classroom", re.I),
}


def _shipped_texts() -> dict[str, str]:
    texts = {"README.md": (ROOT / "README.md").read_text(), "pyproject.toml": (ROOT / "pyproject.toml").read_text()}
    for pattern in ("docs/*.md", "data/**/*.md", "benchmarks/README.md", "scripts/*.sh", "scripts/*.py",
                    "dtscal_lib/**/*.py"):
        for p in sorted(ROOT.glob(pattern)):
            texts[p.relative_to(ROOT).as_posix()] = p.read_text(encoding="utf-8")
    for folder in ("solutions", "notebooks"):
        for p in sorted((ROOT / folder).glob("*.ipynb")):
            cells = json.loads(p.read_text())["cells"]
            texts[f"{folder}/{p.name}"] = "\n\n".join("".join(c["source"]) for c in cells)
    texts.update({"hand-out README.md": rel.STUDENT_README, "hand-out start.sh": rel.START_SH,
                  "bash start.sh --help": rel.START_HELP,
                  "hand-out docs/ta.md": rel.handout_text((ROOT / "docs" / "ta.md").read_text())})
    return texts


@pytest.fixture(scope="module")
def texts():
    found = _shipped_texts()
    assert len(found) > 60 and "hand-out README.md" in found and "dtscal_lib/teaching/command.py" in found
    return found


def _sentence(text: str, at: int) -> str:
    start = max(text.rfind(". ", 0, at), text.rfind("\n\n", 0, at), text.rfind("\n* ", 0, at), 0)
    ends = [e for e in (text.find(". ", at), text.find("\n\n", at)) if e >= 0]
    return text[start:min(ends) if ends else len(text)]


def retired_mentions(texts: dict[str, str]) -> list[str]:
    """Every mention of a retired service outside a sentence that says it is retired."""
    found = []
    for name, text in texts.items():
        for service, pattern in RETIRED.items():
            for m in pattern.finditer(text):
                sentence = _sentence(text, m.start())
                if "retired" not in sentence.lower():
                    found.append(f"{name}: {service} in {' '.join(sentence.split())[:160]!r}")
    return found


_GIT_STEP = re.compile(r"\bgit\s+(?:add|commit)\b")


def git_handin_instructions(texts: dict[str, str]) -> list[str]:
    """Every git hand-in instruction (a `git add` or `git commit` shown to a student) but the kit's one."""
    found = []
    for name, text in texts.items():
        rest = text.replace(GIT_HANDIN, "")  # the kit's instruction, wherever it is shown whole
        for m in _GIT_STEP.finditer(rest):
            shown = " ".join(rest[m.start():].split("\n", 1)[0].split("`", 1)[0].split())
            found.append(f"{name}: {shown[:120]!r}")
    return found


def test_no_text_the_kit_ships_names_a_retired_service_as_a_way_to_hand_in(texts):
    assert retired_mentions(texts) == []
    # the scan finds what it looks for: the hand-out README of before issue 32, and a sentence without "retired"
    old = "* **GitHub Classroom**: this folder is a git repository and your work in `workspace/` is part of it."
    assert len(retired_mentions({"old README": old})) == 1
    assert retired_mentions({"ta.md": "GitHub Classroom, which did this, was retired in 2026."}) == []


def test_every_text_shows_the_same_git_hand_in(texts):
    """README, the hand-out's README, docs/ta.md and `--handin`'s message (command.py) show one git hand-in, the
    workspace committed and pushed (GIT_HANDIN), and no other (`git add -A`, `git add workspace && git commit`
    without the push ...)."""
    assert git_handin_instructions(texts) == []
    for name in ("README.md", "hand-out README.md", "hand-out docs/ta.md"):
        assert GIT_HANDIN in texts[name], name
    assert "handin.GIT_HANDIN" in texts["dtscal_lib/teaching/command.py"]  # the --handin message prints it
    # the check can fail: the three instructions of before issue 32
    old = {"README": "push `workspace/`: `git add -A && git commit -m \"hand in\" && git push`",
           "--handin": "commit and push instead: git add workspace && git commit -m 'hand in' && git push"}
    assert {f.split(':')[0] for f in git_handin_instructions(old)} == set(old)
