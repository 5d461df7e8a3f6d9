"""A reason to doubt a calibration: the one type the kit's judges return.

:func:`dtscal_lib.quality.assess` (the verdict), :func:`dtscal_lib.plausibility.intrinsic_doubts`
and :func:`dtscal_lib.ground.ground_homography_doubts` (the refusals) all answer with
:class:`Finding` objects; their thresholds are in :mod:`dtscal_lib.limits`.

>>> f = Finding("tilt", "bad", "the boards were tilted too little", "tilt the board 20-45 degrees")
>>> str(f)
'the boards were tilted too little. Tilt the board 20-45 degrees'
>>> "tilted too little" in f
True
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

__all__ = ["Finding", "SEVERITIES", "Evidence"]

#: the severities, mildest first: a verdict is the worst severity of its findings ("good" when none)
SEVERITIES = ("good", "doubtful", "bad")


@dataclass
class Finding:
    """One reason for a verdict or a refusal.

    code : short identifier (the verdict's: ``fit``, ``outlier_views``, ``column_offset``, ``row_offset``,
        ``radial``, ``neighbour_correlation``, ``few_views``, ``parallel_views``, ``uncertainty``; the
        refusals': ``shifted_copies``, ``parallel_views``, ``rms``, ``field_of_view``, ``aspect``,
        ``principal_point``, ``focal_std``, ``camera_height``, ``camera_pitch``, ``camera_yaw``,
        ``camera_position``, ``not_a_plane_view``, ``mirrored``)
    severity : ``"doubtful"`` or ``"bad"`` (a refusal is ``"bad"``)
    message : what is wrong, with the numbers
    advice : what to do about it
    views : indices of the views concerned (into the result's views), when it is about views

    ``str(finding)`` is the message and the advice in one sentence (what the refusals were as
    plain strings), and ``"words" in finding`` searches it, so code that handled those strings
    keeps working.
    """

    code: str
    severity: str
    message: str
    advice: str
    views: list[int] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"code": self.code, "severity": self.severity, "message": self.message, "advice": self.advice,
                "views": [int(v) for v in self.views]}

    def warning(self) -> str:
        return f"calibration {self.severity}: {self.message}; what to do: {self.advice}"

    def __str__(self) -> str:
        if not self.advice:
            return self.message
        return f"{self.message}. {self.advice[:1].upper()}{self.advice[1:]}"

    def __contains__(self, words: str) -> bool:
        return words in str(self)


@dataclass
class Evidence:
    """What the verdict needs from the estimator, passed in (:func:`dtscal_lib.result.evidence` makes it), so
    that the judge never calls back into the module that calibrated.

    blocks : the normal equations at the solution (:class:`~dtscal_lib.covariance.NormalBlocks`), for the
        projection uncertainty; None for OpenCV's models and when not asked for
    dist_indices : indices into ``[k1, k2, p1, p2, k3]`` of the distortion terms the result estimated (and
        every refit)
    tilt_spread_deg : largest angle between a board normal and their mean (degrees)
    refit : ``refit(object_points, image_points) -> result``: calibrate other views the same way (the
        checks that leave a column, a row or single corners out)
    """

    blocks: Any
    dist_indices: list[int]
    tilt_spread_deg: float
    refit: Callable[[list, list], Any]
