"""Release machinery: stubs, marker errors, idempotence, the repo in sync, no solution in a release."""

from __future__ import annotations

import re
from pathlib import Path

import nbformat
import pytest
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook, new_output

from dtscal_lib.teaching import release as rel
from dtscal_lib.errors import DtscalError
from nbtools import NOTEBOOKS, ROOT, SOLUTIONS

EXERCISE = '''def double(x):
    """Twice x."""
    y = 0
    ### BEGIN SOLUTION
    y = 2 * x   # the reference answer
    ### END SOLUTION
    return y'''


def toy(exercise_source=EXERCISE, extra_cells=()):
    nb = new_notebook()
    nb.metadata = {"kernelspec": {"name": "python3", "display_name": "Python 3", "language": "python"},
                   "language_info": {"name": "python", "version": "3.11.9"}, "widgets": {"state": {}}}
    imports = new_code_cell("import numpy as np\n%matplotlib inline", metadata={"tags": ["imports"]})
    ex = new_code_cell(exercise_source, metadata={"tags": ["exercise"], "scrolled": True,
                                                  "execution": {"iopub.status.busy": "2024-01-01T00:00:00Z"}})
    ex.outputs = [new_output("stream", name="stdout", text="hello")]
    ex.execution_count = 3
    nb.cells = [new_markdown_cell("# Toy"), imports, ex, new_code_cell("double(2)"), *extra_cells]
    for i, c in enumerate(nb.cells):
        c.id = f"toy-{i}"
    return nb


def test_stub_replaces_region_at_its_indentation():
    sol = toy()
    before = nbformat.writes(sol)
    stu = rel.student_notebook(sol, name="toy.ipynb")
    src = stu.cells[2].source
    assert "2 * x" not in src and "SOLUTION" not in src
    assert '    raise NotImplementedError("double is not written yet")' in src.split("\n")
    assert src.startswith('def double(x):\n    """Twice x."""\n    y = 0\n') and src.endswith("    return y")
    assert nbformat.writes(sol) == before, "the solution notebook must not be modified"


def test_student_notebook_clears_outputs_and_volatile_metadata():
    stu = rel.student_notebook(toy())
    ex = stu.cells[2]
    assert ex.outputs == [] and ex.execution_count is None
    assert dict(ex.metadata) == {"tags": ["exercise"]}
    assert set(stu.metadata) == {"kernelspec", "language_info"}
    # the kernel's language_info whole: JupyterLab rewrites a partial one, opening every notebook as modified
    assert dict(stu.metadata.language_info) == {"name": "python", "version": "3.11.9"}
    nbformat.validate(stu)


def test_student_notebook_is_deterministic():
    assert nbformat.writes(rel.student_notebook(toy())) == nbformat.writes(rel.student_notebook(toy()))


def test_solution_only_cells_are_dropped():
    stu = rel.student_notebook(toy(extra_cells=[new_code_cell("secret = 1", metadata={"tags": ["solution_only"]})]))
    assert all("secret" not in c.source for c in stu.cells)


@pytest.mark.parametrize("source, words", [
    ("def f():\n    ### BEGIN SOLUTION\n    return 1\n", "never closed"),
    ("def f():\n    return 1\n    ### END SOLUTION\n", "no matching"),
    ("def f():\n    ### BEGIN SOLUTION\n    ### BEGIN SOLUTION\n    return 1\n    ### END SOLUTION\n", "was closed"),
    ("def f():\n    return 1\n", "exactly one solution region"),
    ("def f():\n    ## BEGIN SOLUTION\n    return 1\n    ### END SOLUTION\n", "not exactly"),
])
def test_bad_markers_name_the_notebook_and_cell(source, words):
    with pytest.raises(DtscalError, match=re.escape(words)) as err:
        rel.student_notebook(toy(source), name="toy.ipynb")
    assert "toy.ipynb, cell 2" in str(err.value)


def test_markers_outside_exercise_cells_are_errors():
    with pytest.raises(DtscalError, match="outside an 'exercise' or 'practice' cell"):
        rel.student_notebook(toy(extra_cells=[new_code_cell("### BEGIN SOLUTION\nx = 1\n### END SOLUTION")]),
                             name="t")
    with pytest.raises(DtscalError, match="markdown cell"):
        rel.student_notebook(toy(extra_cells=[new_markdown_cell("### BEGIN SOLUTION\nx\n### END SOLUTION")]),
                             name="t")


def _write_toy(folder: Path, name="a.ipynb", nb=None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    nbformat.write(nb or toy(), folder / name)
    return folder / name


def test_generate_is_idempotent_and_check_finds_differences(tmp_path):
    sol, out = tmp_path / "solutions", tmp_path / "notebooks"
    _write_toy(sol)
    [p] = rel.generate_notebooks(sol, out)
    first = p.read_bytes()
    mtime = p.stat().st_mtime_ns
    rel.generate_notebooks(sol, out)
    assert p.read_bytes() == first and p.stat().st_mtime_ns == mtime
    assert rel.check_notebooks(sol, out) == []
    nb = nbformat.read(p, as_version=4)
    nb.cells[3].source = "double(3)"
    nbformat.write(nb, p)
    [d] = rel.check_notebooks(sol, out)
    assert "a.ipynb" in d and "cell 3" in d
    p.unlink()
    assert "missing" in rel.check_notebooks(sol, out)[0]
    rel.generate_notebooks(sol, out)
    _write_toy(out, "stray.ipynb")
    assert any("stray.ipynb has no source" in d for d in rel.check_notebooks(sol, out))


def test_generate_fails_before_writing_anything(tmp_path):
    sol, out = tmp_path / "solutions", tmp_path / "notebooks"
    _write_toy(sol, "a.ipynb")
    _write_toy(sol, "b.ipynb", toy("def f():\n    ### BEGIN SOLUTION\n    return 1\n"))
    with pytest.raises(DtscalError, match="b.ipynb, cell 2"):
        rel.generate_notebooks(sol, out)
    assert not out.exists()


def test_repo_notebooks_are_in_sync_with_solutions():
    assert rel.check_notebooks(SOLUTIONS, NOTEBOOKS) == []


def test_solution_functions_runs_imports_and_exercise_cells(tmp_path):
    p = _write_toy(tmp_path)
    fns = rel.solution_functions(p)
    assert list(fns) == ["double"] and fns["double"](21) == 42
    with pytest.raises(DtscalError, match="no exercise function named triple"):
        rel.solution_functions(p, ["triple"])


def test_inject_solutions_round_trip():
    sol = toy()
    pasted = rel.inject_solutions(rel.student_notebook(sol), sol)
    ns = {}
    exec(pasted.cells[2].source, ns)
    assert ns["double"](5) == 10
    assert "NotImplementedError" not in pasted.cells[2].source


#: input conversions every function starts with: not evidence of a leak
BOILERPLATE = re.compile(r"^[\w, ]+ = (np\.)?(asarray|array|atleast_2d|float|int)\(.*\)$")


def _solution_code_lines() -> list[tuple[str, str]]:
    """Every non-trivial code line inside the repo's solution regions (independent of release.py)."""
    lines = []
    for p in sorted(SOLUTIONS.glob("*.ipynb")):
        for c in nbformat.read(p, as_version=4).cells:
            inside = False
            for line in c.source.split("\n"):
                s = line.strip()
                if s == "### BEGIN SOLUTION":
                    inside = True
                elif s == "### END SOLUTION":
                    inside = False
                elif inside and s and not s.startswith("#") and len(re.sub(r"\s", "", s)) >= 20 \
                        and not BOILERPLATE.match(s):
                    lines.append((p.name, s))
    return lines


def test_release_contains_no_solutions(tmp_path):
    out = rel.release(tmp_path / "student", repo_root=ROOT)
    assert (out / "notebooks").is_dir() and (out / "dtscal_lib").is_dir() and (out / "pyproject.toml").is_file()
    assert not (out / "solutions").exists() and not (out / "tests").exists()
    assert sorted(p.name for p in (out / "notebooks").glob("*.ipynb")) == sorted(
        p.name for p in SOLUTIONS.glob("*.ipynb"))
    assert not list(out.rglob("__pycache__")) and not list(out.rglob("grading"))
    code = _solution_code_lines()
    assert code, "no solution regions found in solutions/"
    leaks = []
    for f in out.rglob("*"):
        if f.is_file():
            try:
                text = f.read_text(encoding="utf-8")
            except UnicodeDecodeError:
                continue
            if f.suffix == ".ipynb":
                text = "\n".join(c.source for c in nbformat.reads(text, as_version=4).cells)
            leaks += [f"{f.relative_to(out)}: {nb}: {s}" for nb, s in code if s in text]
    assert not leaks, "solution code in the release:\n" + "\n".join(leaks)


def _toy_repo(tmp_path: Path, library_text: str = "VALUE = 1\n") -> Path:
    root = tmp_path / "kit"
    _write_toy(root / "solutions", "01_toy.ipynb")
    (root / "dtscal_lib" / "grading").mkdir(parents=True)
    (root / "dtscal_lib" / "__init__.py").write_text(library_text)
    (root / "dtscal_lib" / "grading" / "hidden_cases.py").write_text("CASES = [1, 2, 3]\n")
    (root / "data").mkdir()
    (root / "data" / "truth.yaml").write_text("k: 1\n")
    (root / "pyproject.toml").write_text("[project]\nname = 'toy'\n")
    (root / "README.md").write_text("# toy\n")
    return root


def test_release_layout_on_a_toy_kit(tmp_path):
    root = _toy_repo(tmp_path)
    out = rel.release(tmp_path / "student", repo_root=root)
    files = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file() and p.relative_to(out).parts[0]
                   != ".git")
    assert files == [rel.RELEASE_MARKER, ".gitignore", "README.md", "data/truth.yaml", "dtscal_lib/__init__.py",
                     "notebooks/01_toy.ipynb", "pyproject.toml", "start.sh"]
    assert (out / ".git").is_dir()  # a git repository (test_handout.py checks its commit)
    assert (out / "README.md").read_text() == rel.STUDENT_README and "bash start.sh" in rel.STUDENT_README
    assert "2 * x" not in (out / "notebooks" / "01_toy.ipynb").read_text()


def test_release_detects_solution_code_in_the_library(tmp_path):
    root = _toy_repo(tmp_path, library_text="def double(x):\n    y = 2 * x   # the reference answer\n")
    # the region's line is shorter than 20 characters of code: add a distinctive one
    nb = toy(EXERCISE.replace("y = 2 * x   # the reference answer", "y = (x + x) * 1.0 + 0.0 * x * x * x"))
    nbformat.write(nb, root / "solutions" / "01_toy.ipynb")
    (root / "dtscal_lib" / "__init__.py").write_text("def double(x):\n    y = (x + x) * 1.0 + 0.0 * x * x * x\n")
    with pytest.raises(DtscalError, match="leaked"):
        rel.release(tmp_path / "student", repo_root=root)


def test_release_refuses_unsafe_folders_and_replaces_its_own(tmp_path):
    root = _toy_repo(tmp_path)
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "thesis.tex").write_text("precious")
    with pytest.raises(DtscalError, match="not empty"):
        rel.release(foreign, repo_root=root)
    with pytest.raises(DtscalError, match="inside the kit's solutions"):
        rel.release(root / "solutions" / "out", repo_root=root)
    with pytest.raises(DtscalError, match="contains the kit checkout"):
        rel.release(root, repo_root=root)
    out = rel.release(tmp_path / "student", repo_root=root)
    (out / "leftover.txt").write_text("x")
    rel.release(out, repo_root=root)
    assert not (out / "leftover.txt").exists()


def test_stored_solutions_hold_no_widget_view():
    """A widget view is a random model id per run: stored outputs keep only its text (nbval skips the view)."""
    for p in sorted(SOLUTIONS.glob("*.ipynb")):
        assert rel.WIDGET_VIEW not in p.read_text(), f"{p.name}: run `dtscal release --execute` (it strips them)"


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_execute_twice_changes_no_stored_output(tmp_path, capsys):
    """`release --execute` of notebook 01 (it shows a widget) twice in a row: byte-identical, with progress."""
    import shutil

    sol = tmp_path / "solutions"
    sol.mkdir()
    shutil.copyfile(SOLUTIONS / "01_pinhole_projection.ipynb", sol / "01_pinhole_projection.ipynb")
    rel.execute_solutions(sol, progress=True)
    first = (sol / "01_pinhole_projection.ipynb").read_text()
    assert "executing 01_pinhole_projection.ipynb (1/1)" in capsys.readouterr().err
    rel.execute_solutions(sol)
    assert (sol / "01_pinhole_projection.ipynb").read_text() == first
    assert rel.WIDGET_VIEW not in first and "pinhole explorer" in first


def test_split_stream_outputs_are_joined():
    """A line printed in two stream messages (the kernel flushed in between) is stored as one output, as nbval
    compares it: a re-run's file does not depend on when the kernel flushed."""
    import nbformat

    nb = nbformat.v4.new_notebook()
    cell = nbformat.v4.new_code_cell("print('a', end=''); print()")
    cell.outputs = [nbformat.v4.new_output("stream", name="stdout", text="using your `f`"),
                    nbformat.v4.new_output("stream", name="stdout", text="\n"),
                    nbformat.v4.new_output("stream", name="stderr", text="warning\n"),
                    nbformat.v4.new_output("stream", name="stdout", text="done\n")]
    nb.cells = [cell, nbformat.v4.new_markdown_cell("text")]
    assert rel.coalesce_streams(nb) == 1
    assert [(o.name, o.text) for o in cell.outputs] == [("stdout", "using your `f`\n"), ("stderr", "warning\n"),
                                                        ("stdout", "done\n")]


def test_stored_solutions_hold_no_split_stream():
    for p in sorted(SOLUTIONS.glob("*.ipynb")):
        nb = rel._read(p)
        assert rel.coalesce_streams(nb) == 0, f"{p.name}: run `dtscal release --execute` (it joins them)"
