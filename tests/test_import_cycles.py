"""No import cycle in the library (issue 15): the module-level imports of ``dtscal_lib`` form a DAG.

Imports inside functions (deliberately lazy: cv2-free CLI start, the course layer from ``dtscal course``)
are not part of the graph. A package whose ``__init__`` re-exports its modules must not be imported back by
them (``teaching/selfcheck`` keeps its machinery in ``selfcheck/core.py`` for that reason). The library
never imports the teaching layer (``dtscal_lib/teaching/``), inside functions neither: a folder rule, below.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "dtscal_lib"


def _graph() -> dict[str, set[str]]:
    mods = {}
    for p in ROOT.rglob("*.py"):
        parts = ("dtscal_lib",) + p.relative_to(ROOT).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        mods[name] = p
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for m, p in mods.items():
        pkg = m if p.name == "__init__.py" else m.rsplit(".", 1)[0]
        for node in ast.parse(p.read_text(encoding="utf-8")).body:
            targets = []
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                    module = ".".join(base + ([node.module] if node.module else []))
                else:
                    module = node.module or ""
                targets = [f"{module}.{a.name}" if f"{module}.{a.name}" in mods else module for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            graph[m].update(t for t in targets if t in mods and t != m)
    return graph


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    path: list[str] = []

    def visit(v: str) -> list[str] | None:
        state[v] = 1
        path.append(v)
        for w in sorted(graph[v]):
            if state.get(w) == 1:
                return path[path.index(w):] + [w]
            if w not in state and (found := visit(w)):
                return found
        state[v] = 2
        path.pop()
        return None

    for v in sorted(graph):
        if v not in state and (found := visit(v)):
            return found
    return None


def test_the_graph_reads_the_library():
    graph = _graph()
    assert "dtscal_lib.result" in graph["dtscal_lib.calibration"]  # one way only
    assert "dtscal_lib.teaching.selfcheck.core" in graph["dtscal_lib.teaching.selfcheck.zhang"]


def test_no_import_cycle():
    assert _cycle(_graph()) is None, " -> ".join(_cycle(_graph()))


def test_a_planted_cycle_is_found():
    graph = _graph()
    graph["dtscal_lib.lsq"].add("dtscal_lib.calibration")
    assert _cycle(graph) is not None


# The folder rule (issue 23): the calibration library never imports the teaching layer. Every import counts
# here, those inside functions too; only ``cli.py`` may reach ``teaching.command`` (to register its commands).
ALLOWED = {"cli.py": {"dtscal_lib.teaching.command", "dtscal_lib.teaching.command.add_parsers"}}
OUTSIDE_RULE = ("teaching", "grading")


def _all_imports(path: Path, root: Path) -> set[str]:
    """Every module ``path`` imports, at any depth (relative imports resolved inside ``root``, the library;
    a file outside it, such as the hidden cases ``grading/cases.py``, has none to resolve)."""
    rel = path.relative_to(root).with_suffix("").parts if root in path.parents else ("",)
    pkg = ["dtscal_lib", *rel[:-1]]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg[: len(pkg) - node.level + 1]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module or ""
            out.add(name)
            out.update(f"{name}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return out


def _teaching_imports(root: Path) -> dict[str, list[str]]:
    offenders = {}
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root)
        if rel.parts[0] in OUTSIDE_RULE:
            continue
        hits = {m for m in _all_imports(path, root) if m.split(".")[:2] == ["dtscal_lib", "teaching"]}
        hits -= ALLOWED.get(rel.as_posix(), set())
        if hits:
            offenders[rel.as_posix()] = sorted(hits)
    return offenders


def test_the_library_never_imports_the_teaching_layer():
    assert (ROOT / "teaching" / "course").is_dir() and (ROOT / "teaching" / "selfcheck").is_dir()
    assert _teaching_imports(ROOT) == {}


def test_a_planted_import_of_the_teaching_layer_is_found(tmp_path):
    lib = tmp_path / "dtscal_lib"
    (lib / "sources").mkdir(parents=True)
    (lib / "cli.py").write_text("def f():\n    from .teaching.command import add_parsers\n", encoding="utf-8")
    (lib / "sources" / "x.py").write_text("def g():\n    from ..teaching import course\n", encoding="utf-8")
    (lib / "camera.py").write_text("import dtscal_lib.teaching.selfcheck.core\n", encoding="utf-8")
    assert _teaching_imports(lib) == {
        "camera.py": ["dtscal_lib.teaching.selfcheck.core"],
        "sources/x.py": ["dtscal_lib.teaching", "dtscal_lib.teaching.course"],
    }


# Inside the grader (issue 22): no circle at all, imports inside functions included. ``checks`` (the runtime's
# judges), ``tolerances`` (the offline script deriving the tolerances) and ``material`` once imported each other
# behind function-level imports; the metrics they share live in ``grading/metrics.py``.
def _grading_graph(root: Path) -> dict[str, set[str]]:
    mods = {f"dtscal_lib.grading.{p.stem}": p for p in (root / "grading").glob("*.py") if p.stem != "__init__"}
    graph = {}
    for m, p in mods.items():
        graph[m] = {t for t in _all_imports(p, root) if t in mods and t != m}
        graph[m] |= {t.rsplit(".", 1)[0] for t in _all_imports(p, root) if t.rsplit(".", 1)[0] in mods} - {m}
    return graph


def test_no_import_circle_in_the_grader_even_inside_functions():
    graph = _grading_graph(ROOT)
    assert {"dtscal_lib.grading.checks", "dtscal_lib.grading.metrics", "dtscal_lib.grading.grade"} <= set(graph)
    assert "dtscal_lib.grading.metrics" in graph["dtscal_lib.grading.checks"]
    assert _cycle(graph) is None, " -> ".join(_cycle(graph))


def test_a_planted_function_level_circle_in_the_grader_is_found(tmp_path):
    import shutil

    shutil.copytree(ROOT / "grading", tmp_path / "grading")
    metrics = tmp_path / "grading" / "metrics.py"
    metrics.write_text(metrics.read_text() + "\n\ndef _late():\n    from .checks import num\n    return num\n")
    assert _cycle(_grading_graph(tmp_path)) is not None


# Issue 28, item 10: the two wings. The grader (``dtscal_lib/grading/`` and the instructor's hidden cases in the
# top-level ``grading/`` folder) never imports the teaching wing (``dtscal_lib/teaching/``), nor the teaching wing
# the grader, inside functions neither; what both need (the mistake catalogue ``dtscal_lib/mistakes.py``, the
# rule table ``dtscal_lib/exercise_rules.py``, the notebook format ``dtscal_lib/notebook_format.py``) lives
# outside both. And no import circle anywhere in the library, function-level imports included.
KIT = ROOT.parent
WINGS = {"teaching": "dtscal_lib.teaching", "grading": "dtscal_lib.grading"}


def _wing_files(root: Path) -> dict[str, list[Path]]:
    files = {w: sorted((root / "dtscal_lib" / w).rglob("*.py")) for w in WINGS}
    files["grading"] += sorted((root / "grading").glob("*.py"))  # the hidden cases are the grader's
    return files


def _wing_crossings(root: Path) -> dict[str, list[str]]:
    found = {}
    for wing, files in _wing_files(root).items():
        other = next(m for w, m in WINGS.items() if w != wing)
        for path in files:
            hits = sorted(m for m in _all_imports(path, root / "dtscal_lib") if m == other or m.startswith(other + "."))
            if hits:
                found[path.relative_to(root).as_posix()] = hits
    return found


def test_neither_wing_imports_the_other():
    files = _wing_files(KIT)
    assert len(files["teaching"]) > 10 and KIT / "grading" / "cases.py" in files["grading"]
    assert _wing_crossings(KIT) == {}


def test_a_planted_wing_crossing_is_found(tmp_path):
    for rel, text in {"dtscal_lib/grading/grade.py": "def f():\n    from ..teaching.selfcheck import core\n",
                      "dtscal_lib/teaching/release.py": "import dtscal_lib.grading.material\n",
                      "dtscal_lib/teaching/selfcheck/x.py": "def g():\n    from ...grading import checks\n",
                      "grading/cases.py": "from dtscal_lib.teaching import selfcheck\n"}.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text, encoding="utf-8")
    assert _wing_crossings(tmp_path) == {
        "dtscal_lib/grading/grade.py": ["dtscal_lib.teaching.selfcheck", "dtscal_lib.teaching.selfcheck.core"],
        "dtscal_lib/teaching/release.py": ["dtscal_lib.grading.material"],
        "dtscal_lib/teaching/selfcheck/x.py": ["dtscal_lib.grading", "dtscal_lib.grading.checks"],
        "grading/cases.py": ["dtscal_lib.teaching", "dtscal_lib.teaching.selfcheck"],
    }


def _full_graph(root: Path) -> dict[str, set[str]]:
    """The library's import graph with imports inside functions too (a module importing a package's name
    depends on that package's ``__init__`` and, when the name is a module, on that module)."""
    mods = {}
    for p in root.rglob("*.py"):
        parts = ("dtscal_lib",) + p.relative_to(root).with_suffix("").parts
        mods[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p
    graph = {}
    for m, p in mods.items():
        graph[m] = {t for t in _all_imports(p, root) if t in mods and t != m}
    return graph


SHARED = ("dtscal_lib.mistakes", "dtscal_lib.exercise_rules", "dtscal_lib.notebook_format")


def _wings_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    keep = lambda m: m.startswith(tuple(WINGS.values())) or m in SHARED  # noqa: E731
    return {m: {t for t in ts if keep(t)} for m, ts in graph.items() if keep(m)}


def test_no_import_circle_in_the_wings_even_inside_functions():
    graph = _full_graph(ROOT)
    assert "dtscal_lib.mistakes" in graph["dtscal_lib.teaching.selfcheck.core"]
    assert "dtscal_lib.mistakes" in graph["dtscal_lib.grading.grade"]
    sub = _wings_graph(graph)
    assert _cycle(sub) is None, " -> ".join(_cycle(sub))


def test_a_planted_function_level_circle_in_the_self_checks_is_found(tmp_path):
    import shutil

    shutil.copytree(ROOT / "teaching" / "selfcheck", tmp_path / "teaching" / "selfcheck")
    core = tmp_path / "teaching" / "selfcheck" / "core.py"
    core.write_text(core.read_text() + "\n\ndef _late():\n    from .homography import check_apply_homography\n")
    assert _cycle(_wings_graph(_full_graph(tmp_path))) is not None
