"""The instructor's grading material: hidden cases, weights, and the reference solutions.

It lives only in the instructor's kit: ``grading/cases.py`` (the hidden checks) and
``solutions/*.ipynb`` (the reference functions, loaded like a student's notebook). The
student hand-out contains neither, so a student copy of the kit cannot grade, and says so.
"""

from __future__ import annotations

import re
import runpy
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import DtscalError
from ..exercise_rules import NOTEBOOKS
from .checks import Built, MaterialError, build_check
from .loader import load_submission, useful_import
from .metrics import load as load_tolerances
from .specs import SpecError, typed

#: the exercise notebooks and the functions each one grades
ASSIGNMENTS: dict[str, tuple[str, ...]] = {nb: rules.functions for nb, rules in NOTEBOOKS.items()}


def assignment_of(name: str) -> str | None:
    """The assignment a file name or ``--assignment`` value names (``01``, ``01_pinhole_projection``,
    ``homework-03_intrinsic_calibration.ipynb``...), or None."""
    stem = Path(name).stem.lower()
    for a in ASSIGNMENTS:
        if a in stem or stem == a[:2] or stem == a[3:]:
            return a
    m = re.match(r"^(0[1-5])(?:[_\-. ]|$)", stem)
    if m:
        return next(a for a in ASSIGNMENTS if a.startswith(m.group(1)))
    return None


def find_material(root=None) -> Path:
    """The kit folder holding ``grading/cases.py`` and ``solutions/``; a clear error if absent."""
    from ..paths import repo_root

    root = Path(root) if root is not None else repo_root()
    missing = [p for p in ("grading/cases.py", "solutions") if not (root / p).exists()]
    if missing:
        raise DtscalError(
            f"no grading material in {root} (missing {', '.join(missing)}). `dtscal grade` runs in the "
            "instructor's kit, which holds the hidden cases (grading/cases.py) and the reference solutions "
            "(solutions/); a student hand-out has neither. Run it from the kit checkout or pass --material KIT_DIR."
        )
    return root.resolve()


def reference_functions(nb: Path, names) -> dict:
    """The solution notebook's functions, taken as a student's are (imports and defs only,
    course plumbing left out), but run here: the solutions are trusted."""
    sub = load_submission(nb)
    ns: dict = {"__name__": f"dtscal_reference_{nb.stem}"}
    for src, line in sub.statements:
        if src.lstrip().startswith(("import ", "from ")):
            src = useful_import(src)
        if src is not None:
            try:
                exec(compile("\n" * (line - 1) + src, f"<{nb.name}>", "exec"), ns)
            except Exception as exc:
                raise MaterialError(f"{nb.name}, line {line}: {type(exc).__name__}: {exc}") from exc
    missing = [n for n in names if not callable(ns.get(n))]
    if missing or sub.stubs & set(names):
        raise MaterialError(f"{nb.name} does not define the reference {', '.join(missing or sub.stubs)}")
    return {n: ns[n] for n in names}


@dataclass
class Material:
    """Loaded material: check specs per function, and built checks per assignment (cached)."""

    root: Path
    points: float
    specs: dict[str, list[dict]]
    _built: dict[str, dict[str, list[Built]]] = field(default_factory=dict)
    #: derived tolerances of the noisy checks (grading/tolerances.json, see .tolerances)
    tolerances: dict = field(default_factory=dict)

    @classmethod
    def load(cls, root=None) -> "Material":
        root = find_material(root)
        try:
            ns = runpy.run_path(str(root / "grading" / "cases.py"))
        except Exception as exc:
            raise MaterialError(f"grading/cases.py failed to load: {type(exc).__name__}: {exc}") from exc
        specs = ns.get("CHECKS")
        if not isinstance(specs, dict):
            raise MaterialError("grading/cases.py must define CHECKS = {function name: [check, ...]}")
        for a, funcs in ASSIGNMENTS.items():
            for f in funcs:
                if not specs.get(f):
                    raise MaterialError(f"grading/cases.py has no checks for {f} ({a})")
                for spec in specs[f] if isinstance(specs[f], list) else [specs[f]]:
                    try:  # every check through its kind's dataclass: an unknown key is named here
                        typed(f, spec)
                    except SpecError as exc:
                        raise MaterialError(str(exc)) from None
        try:
            tolerances = load_tolerances(root)
        except ValueError as exc:
            raise MaterialError(f"grading/tolerances.json is not readable: {exc}") from exc
        return cls(root, float(ns.get("POINTS_PER_FUNCTION", 10)), specs, tolerances=tolerances)

    def checks(self, assignment: str) -> dict[str, list[Built]]:
        """Built checks of every function of ``assignment`` (references computed once)."""
        if assignment not in self._built:
            nb = self.root / "solutions" / f"{assignment}.ipynb"
            if not nb.is_file():
                raise MaterialError(f"no reference solution {nb}")
            refs = reference_functions(nb, ASSIGNMENTS[assignment])
            built = {}
            for func in ASSIGNMENTS[assignment]:
                checks = [build_check(func, spec, refs[func], self.tolerances) for spec in self.specs[func]]
                total = sum(c.weight for c in checks)
                for c in checks:  # weights are relative; each function is worth `points`
                    c.weight = round(self.points * c.weight / total, 4)
                built[func] = checks
            self._built[assignment] = built
        return self._built[assignment]
