"""Git hand-in without GitHub Classroom: `dtscal grade --roster` grades each student's repository at the
roster's commit or at the last commit before the deadline.

The students' repositories are local bare repositories made here, their commits dated with
GIT_COMMITTER_DATE (git's own way of stating a commit's time; `git rev-list --until` reads it). The
expected scores are those of `dtscal grade` on the very notebook each commit holds, graded on its own.
"""

from __future__ import annotations

import csv
import json
import os
import shutil
import subprocess

import pytest

from dtscal_lib.cli import main as dtscal
from nbtools import ROOT

SOL = ROOT / "solutions"
WRONG = ROOT / "tests" / "grading_corpus" / "01_pinhole_projection__K_transposed.py"
NB = "01_pinhole_projection.ipynb"
DEADLINE = "2026-12-01T23:59+00:00"


def _git(cwd, *args, date=None):
    env = dict(os.environ, GIT_AUTHOR_NAME="Student", GIT_AUTHOR_EMAIL="s@example.org",
               GIT_COMMITTER_NAME="Student", GIT_COMMITTER_EMAIL="s@example.org", GIT_CONFIG_NOSYSTEM="1",
               HOME=str(cwd))
    if date:
        env["GIT_AUTHOR_DATE"] = env["GIT_COMMITTER_DATE"] = date
    out = subprocess.run(["git", *args], cwd=cwd, env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def _wrong_notebook(path):
    """The solution notebook with the exercise cell replaced by a corpus mistake (K transposed)."""
    nb = json.loads((SOL / NB).read_text())
    cell = next(c for c in nb["cells"] if "exercise" in c.get("metadata", {}).get("tags", []))
    cell["source"] = WRONG.read_text()
    path.write_text(json.dumps(nb))


def _repo(base, student, commits):
    """A bare repository ``base/student.git`` with ``commits``: [(date, {path in repo: source file or None})]."""
    work = base / f"{student}-work"
    work.mkdir()
    _git(work, "init", "--quiet", "-b", "main")
    hashes = []
    for date, files in commits:
        for rel, src in files.items():
            dst = work / rel
            dst.parent.mkdir(parents=True, exist_ok=True)
            if src == "wrong":
                _wrong_notebook(dst)
            else:
                shutil.copy(src, dst)
        _git(work, "add", "-A")
        _git(work, "commit", "--quiet", "-m", f"work of {date}", date=date)
        hashes.append(_git(work, "rev-parse", "HEAD"))
    bare = base / f"{student}.git"
    _git(base, "clone", "--quiet", "--bare", str(work), str(bare))
    return bare, work, hashes


@pytest.fixture(scope="module")
def repos(tmp_path_factory):
    base = tmp_path_factory.mktemp("repos")
    ws = f"workspace/{NB}"
    r = {}
    # alice: right before the deadline, a wrong notebook pushed after it
    r["alice"] = _repo(base, "alice", [("2026-11-30T10:00:00+00:00", {ws: SOL / NB}),
                                       ("2026-12-02T09:00:00+00:00", {ws: "wrong"})])
    # bob: wrong before the deadline; a right copy only in workspace/backups (not graded)
    r["bob"] = _repo(base, "bob", [("2026-11-29T08:00:00+00:00", {ws: "wrong",
                                                                  f"workspace/backups/{NB}": SOL / NB})])
    # carol: her only commit is late
    r["carol"] = _repo(base, "carol", [("2026-12-03T12:00:00+00:00", {ws: SOL / NB})])
    # dave: right, then wrong, both before the deadline; the roster names his first commit
    r["dave"] = _repo(base, "dave", [("2026-11-28T10:00:00+00:00", {ws: SOL / NB}),
                                     ("2026-11-30T10:00:00+00:00", {ws: "wrong"})])
    return base, r


@pytest.fixture(scope="module")
def expected(tmp_path_factory):
    """`dtscal grade` of the right and the wrong notebook, each on its own."""
    d = tmp_path_factory.mktemp("alone")
    shutil.copy(SOL / NB, d / "right.ipynb")
    _wrong_notebook(d / "wrong.ipynb")
    out = {}
    for name in ("right", "wrong"):
        assert dtscal(["grade", str(d / f"{name}.ipynb"), "--assignment", "01", "--json",
                       str(d / f"{name}.json"), "-q"]) == 0
        out[name] = json.loads((d / f"{name}.json").read_text())["score"]
    assert out["right"] == 10 and out["wrong"] < out["right"]  # the pair tells the commits apart
    return out


def _rows(path):
    return {r["student"]: r for r in csv.DictReader(open(path))}


def test_roster_at_deadline_and_commit(repos, expected, tmp_path):
    base, r = repos
    roster = tmp_path / "roster.csv"
    with open(roster, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["student", "repo", "commit"])
        w.writerow(["alice", r["alice"][0].as_uri(), ""])             # a file:// URL
        w.writerow(["bob", os.path.relpath(r["bob"][0], tmp_path), ""])  # a path relative to the CSV
        w.writerow(["carol", str(r["carol"][0]), ""])
        w.writerow(["dave", str(r["dave"][0]), r["dave"][2][0]])
        w.writerow(["erin", str(base / "no-such-repo.git"), ""])
    refs_before = {s: _git(v[0], "for-each-ref") for s, v in r.items()}
    code = dtscal(["grade", "--roster", str(roster), "--deadline", DEADLINE, "--csv", str(tmp_path / "g.csv"),
                   "--jobs", "2", "-q"])
    assert code == 0
    rows = _rows(tmp_path / "g.csv")
    assert sorted(rows) == ["alice", "bob", "carol", "dave", "erin"]  # nobody dropped
    assert float(rows["alice"]["total"]) == expected["right"]  # the commit before the deadline, not the newest
    assert r["alice"][2][0][:10] in rows["alice"]["notes"] and "before the deadline" in rows["alice"]["notes"]
    assert float(rows["bob"]["total"]) == expected["wrong"]  # workspace/backups/ is not graded
    assert float(rows["carol"]["total"]) == 0 and "no commit at or before the deadline" in rows["carol"]["notes"]
    assert float(rows["dave"]["total"]) == expected["right"]  # the roster's commit wins over the deadline
    assert r["dave"][2][0][:10] in rows["dave"]["notes"]
    assert float(rows["erin"]["total"]) == 0 and "cannot clone" in rows["erin"]["notes"]
    # nothing is pushed or written to the students' repositories
    assert {s: _git(v[0], "for-each-ref") for s, v in r.items()} == refs_before


def test_folder_of_clones_newest_commit(repos, expected, tmp_path):
    base, r = repos
    clones = tmp_path / "clones"
    clones.mkdir()
    for s in ("alice", "dave"):
        _git(clones, "clone", "--quiet", str(r[s][0]), s)
    code = dtscal(["grade", "--roster", str(clones), "--csv", str(tmp_path / "g.csv"), "-q"])
    assert code == 0
    rows = _rows(tmp_path / "g.csv")
    # without a deadline the newest commit is graded: both end on the wrong notebook
    assert float(rows["alice"]["total"]) == expected["wrong"] and "newest commit" in rows["alice"]["notes"]
    assert float(rows["dave"]["total"]) == expected["wrong"]
    assert not any(p.name.startswith("grading") for p in clones.rglob("*"))  # no hidden case lands in a clone


@pytest.mark.parametrize("args, words", [
    (["--roster", "x.csv", "--deadline", "tomorrow"], "give a date and time"),
    (["--deadline", DEADLINE], "--deadline goes with --roster"),
])
def test_bad_roster_input(args, words, capsys):
    assert dtscal(["grade", *args]) == 2
    assert words in capsys.readouterr().err


def test_bad_roster_file(tmp_path, capsys):
    bad = tmp_path / "roster.csv"
    bad.write_text("name,url\nalice,x\n")
    assert dtscal(["grade", "--roster", str(bad)]) == 2
    assert "must name the columns student and repo" in capsys.readouterr().err


# --------------------------------------------------------------------------- the deadline's second and zone
@pytest.fixture
def new_york(monkeypatch):
    """This machine's zone set to New York (UTC-5 in December), so a deadline read as UTC is 5 h off."""
    import time

    monkeypatch.setenv("TZ", "America/New_York")
    time.tzset()
    yield
    monkeypatch.undo()
    time.tzset()


def test_a_commit_exactly_at_the_deadline_counts_and_one_second_later_does_not(tmp_path, new_york):
    from dtscal_lib.grading.gitroster import parse_deadline, pick_commit

    # 23:59:00 local in New York is 04:59:00 UTC the next day; the dates carry their own zone (git's format)
    _bare, work, (at, late) = _repo(tmp_path, "ada", [("2026-12-01T23:59:00-05:00", {NB: SOL / NB}),
                                                      ("2026-12-01T23:59:01-05:00", {NB: "wrong"})])
    assert pick_commit(work, deadline=parse_deadline("2026-12-01T23:59"))[0] == at  # zone-less: local time
    assert pick_commit(work, deadline=parse_deadline("2026-12-02T04:59:01Z"))[0] == late
    with pytest.raises(Exception, match="no commit at or before the deadline"):
        pick_commit(work, deadline=parse_deadline("2026-12-01T23:58:59"))


def test_a_zone_less_deadline_is_local_time_and_printed_as_such(new_york):
    from datetime import datetime, timezone

    from dtscal_lib.grading.gitroster import deadline_now_note, parse_deadline, zone_given

    d = parse_deadline("2026-12-01T23:59")
    assert d.astimezone(timezone.utc) == datetime(2026, 12, 2, 4, 59, tzinfo=timezone.utc)
    note = deadline_now_note(d, local=not zone_given("2026-12-01T23:59"))
    assert "2026-12-01T23:59-05:00" in note and "this machine's local time, EST" in note
    assert "2026-12-02 04:59 UTC" in note and "a commit at the deadline counts" in note
    assert zone_given("2026-12-01T23:59Z") and zone_given("2026-12-01T23:59+01:00")
    assert "local time" not in deadline_now_note(parse_deadline("2026-12-01T23:59Z"))
