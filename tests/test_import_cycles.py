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
# here, those inside functions too; only ``cli.py`` may reach ``teaching.command`` (to register its commands),
# and the grader (``grading/``) names mistakes with ``teaching.selfcheck.diagnosis``.
ALLOWED = {"cli.py": {"dtscal_lib.teaching.command", "dtscal_lib.teaching.command.add_parsers"}}
OUTSIDE_RULE = ("teaching", "grading")


def _all_imports(path: Path, root: Path) -> set[str]:
    rel = path.relative_to(root).with_suffix("").parts
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
