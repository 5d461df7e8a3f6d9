"""Read a submission: its import and ``def`` statements only, and what they call.

A submission is a notebook (every code cell is read) or a Python file. The source is only
*parsed* here, in the grader; nothing runs. Top-level code other than imports, function
definitions and assignments of constants (``_IDX = np.array([0, 1, 2])``; plots, widgets,
long loops, ``sys.exit()``, other calls) is dropped, so it never runs; the
kept statements run later inside the sandbox (:mod:`dtscal_lib.grading.child`).

The academic-honesty rule is checked here too, on the syntax tree: an exercise function
that calls a routine solving the exercise for the student (an OpenCV routine or the kit's
own library), directly, through an alias (``import cv2 as c``, ``from cv2 import
findHomography as fh``, ``import dtscal_lib.homography as h``) or through ``getattr`` with
a constant name, gets no credit for that function.
"""

from __future__ import annotations

import ast
import json
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import DtscalError
from ..exercise_rules import (  # noqa: F401 - the rule table's analysis, as the grader's modules know it
    CV2_DENY,
    KIT_ALLOWED,
    _called_names,
    _record_aliases,
    charges,
    forbidden_calls,
    parse_source,
)

#: imports of course plumbing (plots, widgets, the kit's checks) that exercise functions never
#: need: skipped in the sandbox, which saves a second per submission
SKIPPED_IMPORTS = ("matplotlib", "ipywidgets", "IPython", "tqdm", "dtscal_lib")
ALLOWED_KIT_IMPORTS = ("dtscal_lib.duckietown", "dtscal_lib.errors")


#: parsing is bounded before it starts: Python's parser holds ~350 bytes per source byte
#: (measured: 142 MB for a 400 kB one-expression list), so 256 kB of code costs < 100 MB;
#: the longest solution notebook holds 7.2 kB of code (notebook 03), 35x less.
MAX_CODE_CHARS = 256 * 1024
#: a notebook file (outputs, images included): the largest solution notebook is 0.59 MB
MAX_NOTEBOOK_BYTES = 32 * 2 ** 20
#: cells of a notebook: the largest solution notebook has 30 (notebook 04, 16 of code); a notebook of
#: 10,000 cells took 75 s to grade (3 s normally), so 500 (17x the largest) bounds that at ~4 s
MAX_CELLS = 500


def parse(src: str) -> ast.Module:
    """``ast.parse(src)``, never concurrently with another parse of the grader or the self-check, and tried again
    on CPython's transient SystemError (:func:`dtscal_lib.exercise_rules.parse_source`, python/cpython issue 106905)."""
    return parse_source(src)


@dataclass
class Submission:
    """The parsed submission: ``statements`` to run, ``functions`` defined, honesty findings."""

    path: Path
    statements: list[tuple[str, int]] = field(default_factory=list)
    functions: dict[str, ast.FunctionDef] = field(default_factory=dict)
    stubs: set[str] = field(default_factory=set)
    forbidden: dict[str, list[str]] = field(default_factory=dict)
    #: local name -> dotted origin of the submission's top-level imports (``c`` -> ``cv2``)
    aliases: dict[str, str] = field(default_factory=dict)
    dropped: int = 0
    syntax_errors: list[str] = field(default_factory=list)
    #: (code cell number, first line, last line) of each notebook code cell, in the numbering
    #: of ``statements`` (the cells laid end to end); empty for a .py file
    cells: list[tuple[int, int, int]] = field(default_factory=list)

    def where(self, line: int) -> str:
        """``line`` as the student sees it: ``code cell 3, line 5`` in a notebook."""
        for number, first, last in self.cells:
            if first <= line <= last:
                return f"code cell {number}, line {line - first + 1}"
        return f"line {line}"


def _magic_free(src: str) -> str:
    return "\n".join(("# " + ln) if ln.lstrip().startswith(("%", "!")) else ln for ln in src.split("\n"))


def read_cells(path: Path) -> list[tuple[str, int]]:
    """Code of a submission as ``(source, first line)`` blocks (one per notebook code cell)."""
    size = path.stat().st_size
    limit = MAX_CODE_CHARS if path.suffix == ".py" else MAX_NOTEBOOK_BYTES
    if size > limit:
        raise DtscalError(f"{path.name} is {size / 2 ** 20:.1f} MB, more than the {limit / 2 ** 20:g} MB a "
                          "submission may have; hand in the exercise code only")
    if path.suffix == ".py":
        return [(path.read_text(encoding="utf-8", errors="replace"), 1)]
    try:
        nb = json.loads(path.read_text(encoding="utf-8", errors="replace"))
        cells = nb["cells"]
        count = len(cells)
    except (ValueError, KeyError, TypeError, RecursionError) as exc:
        raise DtscalError(f"{path} is not a readable notebook ({type(exc).__name__}: {str(exc)[:200]}); hand in "
                          "the .ipynb file Jupyter saved") from None
    if count > MAX_CELLS:
        raise DtscalError(f"{path.name} has {count} cells, more than the {MAX_CELLS} a submission may have (the "
                          "longest notebook of the course has 30); hand in the course notebook with your exercise "
                          "cells, without the scratch cells")
    blocks, line = [], 1
    for cell in cells:
        if not isinstance(cell, dict) or cell.get("cell_type") != "code":
            continue
        src = cell.get("source", "")
        src = "".join(src) if isinstance(src, list) else str(src)
        blocks.append((_magic_free(src), line))
        line += src.count("\n") + 2
    return blocks


def _is_stub(fn: ast.FunctionDef) -> bool:
    body = [s for s in fn.body if not (isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant))]
    if len(body) != 1 or not isinstance(body[0], ast.Raise) or body[0].exc is None:
        return False
    exc = body[0].exc
    exc = exc.func if isinstance(exc, ast.Call) else exc
    return isinstance(exc, ast.Name) and exc.id == "NotImplementedError"


#: calls allowed in a kept top-level constant (``_IDX = np.array([0, 0, 1])``, ``TOL = math.sqrt(2)``)
CONSTANT_CALLS = frozenset({"array", "asarray", "arange", "eye", "diag", "zeros", "ones", "sqrt", "deg2rad",
                            "radians", "float64", "float32", "int64", "tuple", "list", "dict", "float", "int"})


def _known_names(aliases: dict) -> set[str]:
    """Names a kept constant may use: imports that run in the sandbox (not the course plumbing)."""
    return {a for a, origin in aliases.items() if useful_import(f"import {origin}") is not None}


def _is_constant(node: ast.AST, known: set[str]) -> bool:
    """A top-level assignment of a constant to plain names (kept: exercise functions may use it).

    Only literals, names, attributes, arithmetic and a few cheap constructors with constant
    arguments qualify; anything else at top level (plots, loops, other calls) is dropped."""
    if isinstance(node, ast.Assign):
        targets, value = node.targets, node.value
    elif isinstance(node, ast.AnnAssign) and node.value is not None:
        targets, value = [node.target], node.value
    else:
        return False
    if not all(isinstance(t, ast.Name) or (isinstance(t, ast.Tuple) and all(isinstance(e, ast.Name) for e in t.elts))
               for t in targets):
        return False
    ok = (ast.Constant, ast.Name, ast.Attribute, ast.Tuple, ast.List, ast.Dict, ast.Set, ast.UnaryOp, ast.BinOp,
          ast.Call, ast.Load, ast.operator, ast.unaryop, ast.keyword)
    for n in ast.walk(value):
        if not isinstance(n, ok) or (isinstance(n, ast.Name) and n.id not in known):
            return False
        if isinstance(n, ast.Call):
            f = n.func
            name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""
            if name not in CONSTANT_CALLS:
                return False
        if isinstance(n, ast.BinOp) and isinstance(n.op, ast.Pow):
            return False  # 10 ** 10 ** 10 would never finish
    return True


def load_submission(path) -> Submission:
    """Parse ``path`` (.ipynb or .py) into a :class:`Submission`; runs nothing."""
    path = Path(path)
    sub = Submission(path)
    aliases: dict[str, str] = {}  # local name -> dotted origin ("cv2", "cv2.findHomography", ...)
    constants: set[str] = set()  # names of kept top-level constants
    blocks = read_cells(path)
    code = sum(len(src) for src, _ in blocks)
    if code > MAX_CODE_CHARS:
        raise DtscalError(f"{path.name} holds {code} characters of code, more than the {MAX_CODE_CHARS} a "
                          "submission may have (the longest solution has 7200); nothing was parsed")
    if path.suffix != ".py":
        sub.cells = [(k + 1, first, first + src.count("\n")) for k, (src, first) in enumerate(blocks)]
    for src, first in blocks:
        try:
            tree = parse(src)
        except SyntaxError as exc:
            sub.syntax_errors.append(f"{sub.where(first + (exc.lineno or 1) - 1)}: {exc.msg}")
            continue
        except (MemoryError, RecursionError, ValueError) as exc:
            sub.syntax_errors.append(f"{sub.where(first)}: the code cannot be parsed ({type(exc).__name__})")
            continue
        for node in tree.body:
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                _record_aliases(node, aliases)
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                sub.functions[node.name] = node
                if _is_stub(node):
                    sub.stubs.add(node.name)
                else:
                    sub.stubs.discard(node.name)
            elif _is_constant(node, _known_names(aliases) | constants):
                constants.update(n.id for n in ast.walk(node) if isinstance(n, ast.Name)
                                 and isinstance(n.ctx, ast.Store))
            else:
                sub.dropped += 1
                continue
            seg = ast.get_source_segment(src, node, padded=False)
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.decorator_list:
                seg = "\n".join(src.split("\n")[node.decorator_list[0].lineno - 1: node.end_lineno])
                start = node.decorator_list[0].lineno
            else:
                start = node.lineno
            sub.statements.append((seg, first + start - 1))
    sub.aliases = aliases
    sub.forbidden = charges(sub.functions, aliases).honesty
    return sub


def useful_import(src: str) -> str | None:
    """An import statement without its course plumbing (plots, widgets, the kit's checks):
    the statement itself, a narrower one, or None when nothing useful is left."""
    try:
        node = parse(src).body[0]
    except (SyntaxError, IndexError):
        return src
    if isinstance(node, ast.Import):
        full = [(a, a.name) for a in node.names]
    elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
        full = [(a, f"{node.module}.{a.name}") for a in node.names]
    else:
        return src

    def under(m, roots):
        return any(m == r or m.startswith(r + ".") for r in roots)

    keep = [a for a, m in full if not under(m, SKIPPED_IMPORTS) or under(m, ALLOWED_KIT_IMPORTS)]
    if len(keep) == len(full):
        return src
    if not keep:
        return None
    node.names = keep
    return ast.unparse(node)
