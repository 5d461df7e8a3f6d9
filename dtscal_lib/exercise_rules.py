"""The rules of the exercises: one table per notebook, read by the notebook, the self-check and the grader.

Per notebook (:data:`NOTEBOOKS`):

- **imports** (:data:`ALLOWED_MODULES`): what an exercise function may use. NumPy, ``math`` and the rest of
  Python's standard library, plus the kit's facts (:data:`KIT_ALLOWED`). **SciPy is refused in every
  notebook**: each exercise needs only ``numpy.linalg`` (SVD, eigh, norm, solve, cholesky, det: the spectral
  norm is ``np.linalg.norm(H, 2)``, the polar decomposition is ``U @ Vt`` of an SVD), and the grader's
  sandbox holds exactly what this table lists (issue 28, item 1), so every module allowed here is another
  library and its shared objects inside the sandbox. OpenCV is refused inside exercise functions (importing
  it at the top of the notebook, for plots, is fine); its routines that compute an exercise
  (:data:`CV2_DENY`) are an academic-honesty finding, charged to the function whose own code (or a helper
  of its own that is not another exercise) makes the call, once.
- **returns** (:data:`RETURNS`): numpy arrays, float64 (the rectification maps: float32); a function with two
  outputs returns a tuple of two arrays. A list (nested or not) is *converted* for the values (the points of
  the value checks count) and *refused* by the one return-type rule, with :func:`return_type_problem`'s words.
- **precision**: compute in float64. float32 arithmetic inside fails the value checks of every function but
  ``rectification_maps`` (whose maps are float32 by contract and judged to 0.01 px), in the self-check and
  the grader alike; the hint "float32" is given only at float32's scale (:func:`float32_scale`).

The self-check (``dtscal_lib.teaching.selfcheck``) and the grader (``dtscal_lib.grading``) both import this
module and neither imports the other; the sandbox manifest reads :data:`ALLOWED_MODULES`.
"""

from __future__ import annotations

import ast
import inspect
import sys
import textwrap
import threading
import time
import types
from dataclasses import dataclass

import numpy as np

#: OpenCV routines that solve an exercise (or most of one)
CV2_DENY = frozenset({
    "findHomography", "getPerspectiveTransform", "perspectiveTransform", "warpPerspective",
    "calibrateCamera", "calibrateCameraExtended", "calibrateCameraRO", "initCameraMatrix2D", "projectPoints",
    "undistortPoints", "undistortPointsIter", "undistortImagePoints", "initUndistortRectifyMap", "undistort",
    "getOptimalNewCameraMatrix", "solvePnP", "solvePnPGeneric", "solvePnPRansac", "decomposeHomographyMat",
    "convertPointsFromHomogeneous", "convertPointsToHomogeneous", "fisheye",
})
#: the kit's library ships with the course and holds exercise computations; an exercise function may use
#: none of it but these facts and errors
KIT_ALLOWED = ("dtscal_lib.duckietown", "dtscal_lib.errors")

#: what every exercise notebook allows inside an exercise function (top-level module names; the standard
#: library is allowed as a whole, see :func:`module_allowed`)
ALLOWED_MODULES_COMMON = ("numpy", "math")


@dataclass(frozen=True)
class Returns:
    """What a function returns: ``outputs`` arrays of ``dtype`` (a tuple when there are two)."""

    outputs: int = 1
    dtype: str = "float64"
    shape: str = "(N, 2)"


@dataclass(frozen=True)
class NotebookRules:
    """The rule table of one exercise notebook."""

    functions: tuple[str, ...]
    #: top-level modules an exercise function may import (with Python's standard library)
    modules: tuple[str, ...] = ALLOWED_MODULES_COMMON
    #: per function: the OpenCV routines that compute it (named in the notebook's text)
    shortcuts: tuple[tuple[str, tuple[str, ...]], ...] = ()


NOTEBOOKS: dict[str, NotebookRules] = {
    "01_pinhole_projection": NotebookRules(
        ("project_points",), shortcuts=(("project_points", ("projectPoints",)),)),
    "02_homography": NotebookRules(
        ("apply_homography", "estimate_homography"),
        shortcuts=(("apply_homography", ("perspectiveTransform", "convertPointsFromHomogeneous")),
                   ("estimate_homography", ("findHomography", "getPerspectiveTransform")))),
    "03_intrinsic_calibration": NotebookRules(
        ("intrinsic_constraints", "intrinsics_from_homographies", "extrinsics_from_homography"),
        shortcuts=(("intrinsics_from_homographies", ("calibrateCamera", "initCameraMatrix2D")),
                   ("extrinsics_from_homography", ("decomposeHomographyMat", "solvePnP")))),
    "04_distortion_rectification": NotebookRules(
        ("distort_normalized", "undistort_normalized", "rectification_maps"),
        shortcuts=(("distort_normalized", ("projectPoints",)),
                   ("undistort_normalized", ("undistortPoints", "undistortImagePoints")),
                   ("rectification_maps", ("initUndistortRectifyMap", "undistort")))),
    "05_extrinsic_calibration": NotebookRules(
        ("board_ground_points", "pixel_to_ground", "camera_height_pitch"),
        shortcuts=(("pixel_to_ground", ("perspectiveTransform",)),
                   ("camera_height_pitch", ("decomposeHomographyMat", "solvePnP")))),
}

#: per notebook, the modules an exercise function may import (the grading sandbox's manifest reads this)
ALLOWED_MODULES: dict[str, tuple[str, ...]] = {nb: r.modules for nb, r in NOTEBOOKS.items()}

RETURNS: dict[str, Returns] = {
    "project_points": Returns(),
    "apply_homography": Returns(),
    "estimate_homography": Returns(shape="(3, 3)"),
    "intrinsic_constraints": Returns(shape="(2, 6)"),
    "intrinsics_from_homographies": Returns(shape="(3, 3)"),
    "extrinsics_from_homography": Returns(2, shape="(R (3, 3), t (3,))"),
    "distort_normalized": Returns(),
    "undistort_normalized": Returns(),
    "rectification_maps": Returns(2, "float32", "(map_x, map_y), each (height, width)"),
    "board_ground_points": Returns(),
    "pixel_to_ground": Returns(),
    "camera_height_pitch": Returns(shape="(2,)"),
}

#: the exercise functions that another exercise function of its notebook may call, and that the grader can
#: replace by a stand-in of its own (one bug, one charge: ``dtscal_lib.grading.substitutes``)
STAND_IN_CALLEES = ("apply_homography", "intrinsic_constraints", "distort_normalized", "board_ground_points")


def notebook_of(func: str) -> str:
    return next(nb for nb, r in NOTEBOOKS.items() if func in r.functions)


def module_allowed(top: str, notebook: str) -> bool:
    """May an exercise function of ``notebook`` use the top-level module ``top``?"""
    if top in NOTEBOOKS[notebook].modules:
        return True
    if top in ("cv2", "cv", "dtscal_lib"):  # judged by name: the honesty rule, the kit's allow-list
        return False
    return top in sys.stdlib_module_names


def allowed_words(notebook: str) -> str:
    mods = NOTEBOOKS[notebook].modules
    return ", ".join(("NumPy" if m == "numpy" else m) for m in mods) + " and Python's standard library"


# --------------------------------------------------------------------------- the words (one source)
def honesty_reason(func: str, names) -> str:
    """Why ``func`` gets no credit for calling a solving routine (the self-check and the grader say this)."""
    return (f"no credit: {func} calls {', '.join(names)}, which does the exercise for you "
            "(academic honesty). Write the computation yourself (calling it from tests or plots is fine).")


def module_reason(func: str, names, notebook: str) -> str:
    """Why ``func`` gets no credit for using a module the notebook does not allow."""
    return (f"not allowed: {func} uses {', '.join(names)}; exercise functions of this notebook may use "
            f"{allowed_words(notebook)} only (the grader holds nothing else). SciPy is not needed: "
            "numpy.linalg has svd, eigh, norm (ord=2 is the spectral norm), solve and cholesky.")


def answer_note(value) -> str:
    """How the grader's sandbox describes a returned value that is not a plain array (its harness's ``_encode``
    says the same): "" for an array, a number, a tuple of arrays; "a list", "a tuple", "an ndarray subclass (X)"..."""
    if isinstance(value, (tuple, list)) and 1 <= len(value) <= 4 and \
            any(isinstance(v, (np.ndarray, tuple)) for v in value):  # several outputs
        if isinstance(value, list):
            return "a list"
        return next((f"{n} inside the tuple" for n in (answer_note(v) for v in value) if n), "")
    if isinstance(value, np.ndarray):
        return f"an ndarray subclass ({type(value).__name__})" if type(value) is not np.ndarray else ""
    if isinstance(value, (float, int, np.floating, np.integer)) and not isinstance(value, bool) or value is None:
        return ""
    return f"a {type(value).__name__}"


def return_type_problem(func: str, value, note: str | None = None) -> str:
    """The one return-type rule: "" when ``value`` is what ``func`` must return, else what is wrong.

    The self-check passes the raw value; the grader passes the value its sandbox decoded (arrays) and the
    sandbox's ``note`` on it. Both get the same words."""
    r = RETURNS[func]
    want = (f"a tuple of {r.outputs} numpy arrays {r.shape}, dtype {r.dtype}" if r.outputs > 1 else
            f"a numpy array {r.shape} of dtype {r.dtype}")
    note = answer_note(value) if note is None else note
    if note:
        return (f"should return {want}, got {note}: return numpy arrays (np.asarray(..., dtype=np.{r.dtype})); "
                "a list's values are read, but the return type is part of the contract")
    parts = list(value) if isinstance(value, tuple) else [value]
    if len(parts) != r.outputs or not all(isinstance(p, np.ndarray) for p in parts):
        got = (f"a tuple of {len(parts)}" if isinstance(value, tuple) else
               f"a {type(value).__name__}" if not isinstance(value, np.ndarray) else "one array")
        return f"should return {want}, got {got}"
    for p in parts:
        if str(p.dtype) != r.dtype:
            return f"should return {want}, got dtype {p.dtype}"
    return ""


def raises_problem(error: str) -> str:
    """A raised error that is not the ValueError the contract asks for (the self-check and the grader say this):
    "" for ``ValueError: <a message of the student's>``; a ValueError from ``math`` (a square root of a negative
    number on too few views) is not one."""
    if error.startswith("ValueError") and "math domain error" not in error:
        return ""
    return f"should raise ValueError saying what is wrong (check the number of views first), raised {error}"


#: the precision contract: the relative error (to the answer's largest entry) a float64 computation stays within
#: on the exact probes of the mistake catalogue. Measured (``tests/test_exercise_rules.py``): every solution and
#: correct corpus formulation <= 4e-14 there; float32 arithmetic inside >= 1e-8 (its epsilon is 1.2e-7)
PRECISION_RTOL = 1e-9
#: relative errors up to this are what float32 arithmetic leaves (its epsilon through a chain of operations);
#: above it an answer is a mistake of its own, judged by the value checks
FLOAT32_BAND = 1e-4


def float32_sized(err: float) -> bool:
    """Is a relative error ``err`` what float32 arithmetic leaves (and not round-off of float64, nor a real
    mistake)? The hint "float32" is given only then."""
    return PRECISION_RTOL < err <= FLOAT32_BAND


def relative_error(got_parts, want_parts) -> float | None:
    """The largest relative error over every part of an answer (None when the shapes differ or a value is
    not finite)."""
    worst = 0.0
    for g, w in zip(got_parts, want_parts):
        g, w = np.asarray(g, float), np.asarray(w, float)
        if g.shape != w.shape or not np.all(np.isfinite(g)):
            return None
        scale = float(np.abs(w).max(initial=0.0)) or 1.0
        worst = max(worst, float(np.abs(g - w).max(initial=0.0)) / scale)
    return worst


# --------------------------------------------------------------------------- reading code (no code runs)
def _record_aliases(node, aliases: dict) -> None:
    if isinstance(node, ast.Import):
        for a in node.names:
            if a.asname:
                aliases[a.asname] = a.name
            else:
                aliases[a.name.split(".")[0]] = a.name.split(".")[0]
    else:
        mod = node.module or ""
        for a in node.names:
            aliases[a.asname or a.name] = f"{mod}.{a.name}" if mod else a.name


def _dotted(node, aliases: dict, strict: bool = False) -> str | None:
    """``cv2.findHomography`` for ``c.findHomography`` when ``import cv2 as c``; None if not a name chain
    (``strict``: nor a chain from an imported name)."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "__import__" \
            and node.args and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str):
        base = node.args[0].value
    elif isinstance(node, ast.Name):
        if strict and node.id not in aliases:
            return None
        base = aliases.get(node.id, node.id)
    else:
        return None
    return ".".join([base, *reversed(parts)])


def denied(name: str | None) -> bool:
    """Is ``name`` (a dotted origin) a routine solving an exercise?"""
    if not name:
        return False
    parts = name.split(".")
    if parts[0] in ("cv2", "cv"):
        return len(parts) > 1 and parts[1] in CV2_DENY
    if parts[0] == "dtscal_lib" and len(parts) > 1:
        return not any(name == m or name.startswith(m + ".") for m in KIT_ALLOWED)
    return False


def _most_specific(hits: set) -> list[str]:
    return sorted(h for h in hits if not any(o != h and o.startswith(h + ".") for o in hits))


def _shadowed(fn: ast.AST, aliases: dict) -> dict:
    """The notebook's aliases as ``fn`` sees them: a name the function binds itself (an argument, an assignment
    target) is its own variable, not the notebook's module (a student's local ``cam = X @ R.T`` beside the
    notebook's ``from dtscal_lib import camera as cam`` was charged as a call of the kit's camera); a name
    assigned a module or a routine (``c = cv2``, ``f = cv2.findHomography``) becomes an alias of it."""
    local = dict(aliases)
    args = getattr(fn, "args", None)
    if isinstance(args, ast.arguments):
        for a in args.posonlyargs + args.args + args.kwonlyargs + [x for x in (args.vararg, args.kwarg) if x]:
            local.pop(a.arg, None)
    for node in ast.walk(fn):
        if isinstance(node, ast.Name) and isinstance(node.ctx, (ast.Store, ast.Del)):
            local.pop(node.id, None)
    for node in ast.walk(fn):
        if isinstance(node, ast.Assign):
            origin = _dotted(node.value, aliases, strict=True)
            if origin:
                for target in node.targets:
                    if isinstance(target, ast.Name):
                        local[target.id] = origin
    return local


def _scan(fn: ast.AST, aliases: dict, notebook: str | None) -> tuple[list[str], list[str]]:
    """(solving routines, modules the notebook does not allow) that ``fn`` names."""
    local = _shadowed(fn, aliases)
    for node in ast.walk(fn):  # imports inside the function count too
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            _record_aliases(node, local)
            if notebook is not None:
                for a in node.names:
                    mod = a.name if isinstance(node, ast.Import) else f"{node.module or ''}.{a.name}"
                    local.setdefault(f"<import {mod}>", mod)
    hits, modules = set(), set()
    for node in ast.walk(fn):
        if isinstance(node, (ast.Attribute, ast.Name)):
            name = _dotted(node, local)
            if name and denied(name) and name.count(".") >= 1:
                hits.add(name)
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "getattr" \
                and len(node.args) >= 2 and isinstance(node.args[1], ast.Constant) \
                and isinstance(node.args[1].value, str):
            base = _dotted(node.args[0], local)
            if base and denied(f"{base}.{node.args[1].value}"):
                hits.add(f"{base}.{node.args[1].value}")
        if notebook is not None and isinstance(node, (ast.Attribute, ast.Name)):
            strict = _dotted(node, local, strict=True)
            if strict and not module_allowed(strict.split(".")[0], notebook):
                modules.add(strict)
    if notebook is not None:
        modules |= {m for k, m in local.items() if k.startswith("<import ")
                    and not module_allowed(m.split(".")[0], notebook)}
    modules = {m for m in modules if not denied(m) and not any(h.startswith(m + ".") or h == m for h in hits)
               and not any(m == k or m.startswith(k + ".") for k in KIT_ALLOWED) and m != "dtscal_lib"}
    return _most_specific(hits), _most_specific(modules)


def forbidden_calls(fn: ast.AST, aliases: dict) -> list[str]:
    """Names of solving routines that ``fn`` uses (calls, or takes via getattr), sorted."""
    return _scan(fn, aliases, None)[0]


def _called_names(fn: ast.AST) -> set[str]:
    return {n.id for n in ast.walk(fn) if isinstance(n, ast.Name)}


@dataclass
class Charges:
    """Per function: the solving routines and the disallowed modules its code reaches."""

    honesty: dict[str, list[str]]
    modules: dict[str, list[str]]


def charges(functions: dict[str, ast.AST], aliases: dict, notebook: str | None = None,
            exercises: tuple[str, ...] = (), own_aliases: dict[str, dict] | None = None) -> Charges:
    """What each function of a submission is charged with: the routines it reaches through its own code and
    its own helpers at any depth (``"cv2.x (through helper)"``), never through another exercise function
    that the grader replaces by a stand-in (that function is charged itself: one call, one charge)."""
    own_aliases = own_aliases or {}
    scans = {name: _scan(fn, own_aliases.get(name, aliases), notebook) for name, fn in functions.items()}
    out = Charges({}, {})
    for name in functions:
        hits, mods = set(scans[name][0]), set(scans[name][1])
        seen, todo = {name}, [name]
        while todo:
            for callee in _called_names(functions[todo.pop()]):
                if callee in functions and callee not in seen and not (callee in exercises and callee != name
                                                                        and callee in STAND_IN_CALLEES):
                    seen.add(callee)
                    todo.append(callee)
                    hits.update(f"{h} (through {callee})" for h in scans[callee][0])
                    mods.update(f"{h} (through {callee})" for h in scans[callee][1])
        if hits:
            out.honesty[name] = sorted(hits)
        if mods:
            out.modules[name] = sorted(mods)
    return out


# --------------------------------------------------------------------------- a live function (the self-check)
def _origin(value) -> str | None:
    """The dotted origin of a notebook global: a module's name, or a function's ``module.name``."""
    if isinstance(value, types.ModuleType):
        return value.__name__
    mod = getattr(value, "__module__", None)
    name = getattr(value, "__name__", None)
    if isinstance(mod, str) and isinstance(name, str) and not mod.startswith("dtscal_"):
        mod = "cv2" if mod.startswith("cv2") else mod
        return f"{mod}.{name}"
    if isinstance(mod, str) and mod.startswith("dtscal_lib") and isinstance(name, str):
        return f"{mod}.{name}"
    return None


#: one ``ast.parse`` at a time in this process, for the grader and the self-check alike: CPython's parser is
#: not safe to call from two threads at once (python/cpython issue 106905, "AST constructor recursion depth
#: mismatch": 44 of 1,240 concurrent loads raised SystemError under ``dtscal grade --jobs 2``)
PARSE_LOCK = threading.Lock()
#: a compile that does not take the lock (the first import of a module, from another thread) can still meet a
#: parse: the SystemError is then the interpreter's, transient, and the parse is tried again
PARSE_TRIES = 5


def parse_source(text: str) -> ast.Module:
    """``ast.parse(text)`` under :data:`PARSE_LOCK`, tried again on CPython's transient SystemError."""
    for attempt in range(PARSE_TRIES):
        with PARSE_LOCK:
            try:
                return ast.parse(text)
            except SystemError:
                if attempt == PARSE_TRIES - 1:
                    raise
        time.sleep(0.01 * (attempt + 1))
    raise AssertionError("unreachable")


def _source_tree(fn) -> ast.AST | None:
    """The syntax tree of ``fn`` alone (its ``def``, or its ``lambda`` among the statement's), or None."""
    try:
        src = textwrap.dedent(inspect.getsource(fn))
    except (OSError, TypeError):
        return None
    for text in (src, f"(\n{src}\n)"):  # a lambda's lines may be a fragment of a longer expression
        try:
            tree = parse_source(text)
            break
        except SyntaxError:
            continue
    else:
        return None
    code = getattr(fn, "__code__", None)
    if fn.__name__ == "<lambda>" and code is not None:
        names = list(code.co_varnames[:code.co_argcount])
        found = [n for n in ast.walk(tree) if isinstance(n, ast.Lambda) and [a.arg for a in n.args.args] == names]
    else:
        found = [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))
                 and n.name == fn.__name__]
    return found[0] if len(found) == 1 else None


def _user_module(name) -> bool:
    """Is the module called ``name`` the student's code (a notebook's ``__main__``, a script), not a library?"""
    if not isinstance(name, str) or not name:
        return False
    if name == "__main__":  # a notebook's cells (Jupyter's __main__ may be a launcher in site-packages)
        return True
    top = name.split(".")[0]
    if top in ("numpy", "cv2", "scipy", "dtscal_lib", "builtins") or top in sys.stdlib_module_names:
        return False
    path = str(getattr(sys.modules.get(name), "__file__", "") or "")
    return not any(part in path for part in ("site-packages", "dist-packages"))


def _user_code(f) -> bool:
    """Is ``f`` the student's code (a notebook's or a script's function), not a library's?"""
    return _user_module(getattr(f, "__module__", None))


def _aliases_of(glb: dict) -> dict:
    """A namespace's imports as dotted origins (``np`` -> ``numpy``); the student's own code is not an import."""
    return {k: o for k, v in list(glb.items()) if not k.startswith("__")
            and not (not isinstance(v, types.ModuleType) and _user_code(v)) and (o := _origin(v))}


def live_charges(func: str, fn) -> tuple[str, str]:
    """(honesty reason, module reason) for a live exercise function (the self-check's view of the grader's
    rule): the function's source and its notebook helpers' are read, its globals name the imports."""
    glb = getattr(fn, "__globals__", None)
    tree = _source_tree(fn)
    if glb is None or tree is None:
        return "", ""
    notebook = notebook_of(func)
    functions, names_of = {func: tree}, {func: _aliases_of(glb)}
    todo = [(tree, glb)]
    while todo:  # the student's own functions it calls (helpers and other exercise functions), at any depth
        node, where = todo.pop()
        for name in sorted(_called_names(node)):
            f = where.get(name)
            if name not in functions and isinstance(f, types.FunctionType) and _user_code(f):
                sub = _source_tree(f)
                if sub is not None:
                    functions[name], names_of[name] = sub, _aliases_of(f.__globals__)
                    todo.append((sub, f.__globals__))
    found = charges(functions, {}, notebook, NOTEBOOKS[notebook].functions, names_of)
    hon = found.honesty.get(func)
    mods = found.modules.get(func)
    return (honesty_reason(func, hon) if hon else "", module_reason(func, mods, notebook) if mods else "")


def rules_markdown(notebook: str) -> str:
    """The notebook's rule cell, generated from its table (``tests/test_exercise_rules.py`` compares the
    notebook's text with it)."""
    r = NOTEBOOKS[notebook]
    lines = ["### The rules of the exercises (the self-check and the grader apply the same)", "",
             f"- **Imports** inside an exercise function: {allowed_words(notebook).replace('math', '`math`')}. "
             "No SciPy (`numpy.linalg` has `svd`, `eigh`, `norm`, `solve`, `cholesky`), no OpenCV "
             "(`import cv2` at the top serves the notebook's drawings)."]
    if r.shortcuts:
        lines.append("- **Forbidden shortcuts**: " + "; ".join(
            f"`{f}` may not call " + " or ".join(f"`cv2.{c}`" for c in cv) for f, cv in r.shortcuts)
            + ". Each computes the exercise: the function that makes the call gets no credit (that function "
            "only, once).")
    lines += ["- **Returns**: numpy arrays, " + "; ".join(
                  f"`{f}`: {RETURNS[f].shape} {RETURNS[f].dtype}" for f in r.functions)
              + ". A list is refused by the return-type check (its values still count).",
              "- **Precision**: compute in float64; float32 arithmetic inside fails the checks."]
    return "\n".join(lines)
