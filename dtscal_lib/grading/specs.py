"""The hidden cases, typed: one dataclass per check kind (the ``judge`` of a check in ``grading/cases.py``).

``grading/cases.py`` stays a plain dictionary of checks (the nbgrader export and the Gradescope bundle copy
it as it is); every check is read through the dataclass of its kind before anything is built, so a key no
kind knows (``camer="4k"``, ``atl=1e-6``) is an error that names it, never a check graded silently with
the defaults; an unknown camera or lens is named too.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from ..errors import DtscalError


class SpecError(DtscalError):
    """A check of the grading material is malformed (an instructor's problem)."""


@dataclass(frozen=True)
class Check:
    """What every check has: its name (shown to the student), weight (points, relative) and seed."""

    name: str
    weight: float = 1.0
    seed: int | None = None
    judge: str = "close"
    #: what a failing case tests, in words (default: derived from the inputs, ``checks.about``)
    about: str | None = None


@dataclass(frozen=True)
class Inputs(Check):
    """The inputs' parameters (see ``checks.inputs_and_truth``)."""

    views: int | None = None
    n: int | None = None
    camera: str | None = None
    depth: tuple | None = None
    distance: tuple | None = None
    random_scale: bool = False
    random_H: bool = False
    sigma: float | None = None
    offset: float | None = None
    span: float | None = None
    scale: float | None = None
    #: the homographies are scaled so that H[2, 2] = h33 (catches ``H /= H[2, 2]`` done in place)
    h33: float | None = None
    #: camera_height_pitch: the range of pitches below the horizon, degrees (negative: pitched up)
    pitch: tuple | None = None
    lens: str | None = None
    dist: tuple | None = None
    region: str | None = None
    radius: float | None = None
    alpha: float | None = None
    K: tuple | None = None
    size: tuple | None = None
    boards: list | None = None


@dataclass(frozen=True)
class Close(Inputs):
    """The answers within ``atol + rtol |reference|`` of the reference's."""

    atol: float = 0.0
    rtol: float = 1e-9


@dataclass(frozen=True)
class Unchanged(Inputs):
    """The inputs are the same after the call."""


@dataclass(frozen=True)
class Dtype(Inputs):
    """The return type (the rule table's), and the shape."""

    dtype: str = "float64"


@dataclass(frozen=True)
class Raises(Inputs):
    """The call raises ValueError."""


@dataclass(frozen=True)
class Scaled(Inputs):
    """H[2, 2] = 1."""


@dataclass(frozen=True)
class TruthH(Inputs):
    """Noisy correspondences: within the derived tolerance of the true homography."""


@dataclass(frozen=True)
class TruthK(Inputs):
    """Noisy homographies: within the derived tolerance of the true K."""


@dataclass(frozen=True)
class TruthPose(Inputs):
    """Noisy homographies: within the derived tolerances of the true pose."""


@dataclass(frozen=True)
class Precision(Check):
    """The precision contract on the mistake catalogue's exact probes (no inputs of its own)."""


KINDS: dict[str, type[Check]] = {"close": Close, "unchanged": Unchanged, "dtype": Dtype, "raises": Raises,
                                 "scaled": Scaled, "truth_H": TruthH, "truth_K": TruthK, "truth_pose": TruthPose,
                                 "precision": Precision}
#: the values some keys may take (checked here, so a typo is named before a case is drawn)
CHOICES = {"camera": ("duckie", "skewed", "4k", "rectified"), "lens": ("duckiebot", "tangential", "radial_k3", "none"),
           "region": ("image",), "dtype": ("float64", "float32")}


def typed(func: str, spec: dict) -> dict:
    """``spec`` read through its kind's dataclass: the same dictionary, or :class:`SpecError` naming what is
    wrong (an unknown kind, key or value, a missing name or seed)."""
    where = f"grading/cases.py, {func}, check {spec.get('name', '?')!r}"
    if not isinstance(spec, dict):
        raise SpecError(f"{where}: a check is a dict(...), got {type(spec).__name__}")
    kind = spec.get("judge", "close")
    cls = KINDS.get(kind)
    if cls is None:
        raise SpecError(f"{where}: unknown judge {kind!r}; the kinds are {', '.join(KINDS)}")
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(spec) - known)
    if unknown:
        raise SpecError(f"{where}: unknown key(s) {', '.join(repr(k) for k in unknown)} for a {kind!r} check; "
                        f"its keys are {', '.join(sorted(known))}")
    if "name" not in spec:
        raise SpecError(f"{where}: every check needs a name")
    if cls is not Precision and spec.get("seed") is None:
        raise SpecError(f"{where}: a {kind!r} check needs a seed (its inputs are drawn from it)")
    for key, values in CHOICES.items():
        if key in spec and spec[key] not in values:
            raise SpecError(f"{where}: {key}={spec[key]!r} is not one of {', '.join(map(repr, values))}")
    cls(**spec)
    return spec
