"""The hand-out never contains the grading material, and cannot grade."""

from __future__ import annotations

import re

import pytest

from dtscal_lib.cli import main as dtscal
from nbtools import ROOT

CASES = ROOT / "grading" / "cases.py"
#: a whole run of digits not after a digit or a point: a seed token is found as one of these exactly when
#: ``(?<![0-9.])SEED(?![0-9])`` matches (same boundaries, the run ends where the digits end)
_NUMBER = re.compile(rb"(?<![0-9.])[0-9]+")


def _hidden_tokens() -> set[bytes]:
    """What identifies the hidden cases: every seed, and the material's own names."""
    text = CASES.read_text()
    seeds = set(re.findall(r"seed=(\d+)", text))
    assert len(seeds) >= 40
    return {s.encode() for s in seeds} | {b"POINTS_PER_FUNCTION", b"Hidden grading cases"}


@pytest.fixture(scope="module")
def handout(tmp_path_factory):
    out = tmp_path_factory.mktemp("handout") / "course"
    assert dtscal(["release", str(out)]) == 0
    return out


def test_handout_holds_no_hidden_case(handout):
    tokens = _hidden_tokens()
    # .git holds the same files, zlib-compressed (the hand-out's one commit): their plain copies are scanned
    files = [p for p in handout.rglob("*") if p.is_file() and ".git" not in p.relative_to(handout).parts]
    assert len(files) > 20
    hits = []
    for p in files:
        data = p.read_bytes()
        runs = None
        for tok in tokens:
            if tok.isdigit():  # one pass per file for the ~50 seeds (a search per seed took ~20 s on the bags)
                runs = set(_NUMBER.findall(data)) if runs is None else runs
                found = tok in runs
            else:
                found = re.search(rb"(?<![0-9.])" + re.escape(tok) + rb"(?![0-9])", data) is not None
            if found:
                hits.append(f"{p.relative_to(handout)}: {tok.decode()}")
    assert not hits, hits
    assert not (handout / "grading").exists() and not (handout / "solutions").exists()


def test_handout_cannot_grade(handout, capsys, tmp_path):
    nb = handout / "notebooks" / "01_pinhole_projection.ipynb"
    assert dtscal(["grade", str(nb), "--material", str(handout)]) == 2
    err = capsys.readouterr().err
    assert "no grading material" in err and "instructor" in err
