"""How good is a calibration: a verdict with reasons, and the projection uncertainty over the image.

A small RMS does not make a calibration good (the lesson of mrcal's documentation): a model that
cannot follow the lens, or corners that the detector put in the wrong place in the same way view
after view, can fit with a modest RMS and still move every pixel by more than the reported standard
deviations admit. So :func:`assess` judges a :class:`~dtscal_lib.calibration.CalibrationResult` by

1. **its residuals against the corner noise of these very images.** The noise model: every detected
   corner coordinate is the true one plus independent zero-mean Gaussian noise of one standard
   deviation ``sigma_noise`` (pixels, per coordinate), the same for every corner. ``sigma_noise`` is
   measured without any camera model (:func:`corner_noise`): on a smooth image of a regular grid
   every interior corner is predicted by the least-squares quadratic through its 8 grid neighbours
   (perspective and lens distortion are smooth; on the symmetric ring the odd third-order terms
   cancel, so only fourth-order curvature is left, far below the noise), and the robust spread of
   those predictions' errors, divided by the prediction's own noise gain, is ``sigma_noise``. A fit
   whose residual ``sigma`` is near ``sigma_noise`` explains the data; a fit several times worse has
   something the model cannot absorb.
2. **residuals that are systematic, not noise**: views whose own RMS is far above the others (named);
   a column or row of corners offset the same way in many views (named with its views: a detector
   pulled by the board's edge does this); a radial pattern the distortion model cannot absorb;
   neighbouring corners that share one error.
3. **the data**: too few views, boards all nearly parallel.
4. **the projection uncertainty** (:func:`projection_uncertainty`, mrcal's uncertainty maps): how far
   the projection of a fixed 3-D point moves, 1 sigma, when the parameters move within their
   covariance; "bad" only where the robot looks (:func:`dtscal_lib.uncertainty.robot_view`), advice at
   the image corners no board reached.

The checks are named rules run in order (:data:`dtscal_lib.rules.RULES`); the judge gets what it needs
from the estimator passed in (:class:`~dtscal_lib.findings.Evidence`, made by
:func:`dtscal_lib.result.evidence`) and never calls back into it.

The verdict is the worst severity of the findings: ``"good"`` when there is none, else
``"doubtful"`` or ``"bad"``; every finding carries advice (which views to drop, where to hold the
board next).

Example: eight well-tilted views, but every board in the middle of the image, so the lower half of the
image, where a Duckiebot sees the road, is extrapolated: bad, and the verdict says where to hold the board.

>>> import numpy as np
>>> from dtscal_lib import camera, duckietown as dt
>>> from dtscal_lib.boards import DUCKIETOWN_BOARD
>>> from dtscal_lib.calibration import calibrate
>>> rng = np.random.default_rng(1)
>>> obj = DUCKIETOWN_BOARD.object_points()
>>> poses = [([a, b, 0.1 * k], [-0.1 + 0.03 * a, -0.06, 0.3 + 0.02 * k])
...          for k, (a, b) in enumerate([(0.4, 0.1), (-0.4, 0.2), (0.1, -0.4), (-0.2, -0.3), (0.3, 0.35),
...                                      (-0.35, -0.1), (0.2, -0.2), (-0.1, 0.4)])]
>>> img = [camera.project_points(obj, r, t, dt.default_K(), dt.default_dist()) + rng.normal(0, 0.05, (35, 2))
...        for r, t in poses]
>>> q = calibrate([obj] * len(img), img, dt.IMAGE_SIZE).quality()
>>> q.verdict, [f.code for f in q.findings]
('bad', ['robot_view'])
>>> print(q.findings[0].advice)
collect more views filling the lower half of the image, tilted
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import CalibrationError
from .findings import Evidence, Finding
from .limits import (  # noqa: F401  (re-exported: the verdict's thresholds, one table in dtscal_lib.limits)
    CORNER_SIGMA_DOUBTFUL, FIT_RATIO_BAD, FIT_RATIO_DOUBTFUL, MIN_GOOD_VIEWS, NEIGHBOUR_CORRELATION, OFFSET_VIEW_SHARE,
    OFFSET_Z, RADIAL_FRACTION, RADIAL_Z, ROBOT_SHIFT_BAD_PX, ROBOT_VIEW_SIGMA_BAD, ROBOT_VIEW_SIGMA_DOUBTFUL,
    SYSTEMATIC_RATIO_BAD, TILT_BAD_DEG, TILT_DOUBTFUL_DEG, VIEW_OUTLIER_FACTOR)
from .rules import (  # noqa: F401  (re-exported: the verdict's checks as they were here)
    NOISE_FLOOR_PX, corner_noise, grid_indices, leave_out_outlier_corners, prepare, residuals, residuals_of,
    run_rules)
from .uncertainty import (  # noqa: F401  (re-exported: the projection uncertainty as it was here)
    CONSEQUENCE_DISTANCES_M, NOMINAL_CAMERA_HEIGHT_M, NOMINAL_CAMERA_PITCH_DEG, NOMINAL_CAMERA_X_M, REGION_NAMES,
    UncertaintyMap, consequences, image_region, monte_carlo_projection, projection_uncertainty, uncertainty_map,
    worst_direction_sigma)

__all__ = ["Finding", "Quality", "UncertaintyMap", "assess", "corner_noise", "residuals", "grid_indices",
           "leave_out_outlier_corners", "projection_uncertainty", "image_region", "consequences", "explain",
           "REGION_NAMES"]

_SEVERITY = {"good": 0, "doubtful": 1, "bad": 2}


@dataclass
class Quality:
    """What :func:`assess` found."""

    verdict: str
    findings: list[Finding]
    noise_sigma: float
    noise_points: int
    fit_sigma: float
    per_view_rms: np.ndarray
    residuals: list[np.ndarray]
    uncertainty: UncertaintyMap | None
    corner_counts: np.ndarray  # (3, 3) observed corners per ninth of the image
    help_region: str
    tilt_spread_deg: float
    #: the report page when one was written (:func:`dtscal_lib.report.quality_for_run`)
    report_path: object = None
    #: what the calibration means for a Duckiebot (:func:`consequences`); None without the uncertainty
    consequences: dict | None = None
    #: remarks that do not change the verdict (severity "good"): what explains a residual above the noise
    notes: list = field(default_factory=list)
    #: the calibration repeated without the outlier corners (finding ``outlier_corners``), else None
    without_outlier_corners: object = None
    #: the richer models fitted to these corners (:mod:`dtscal_lib.richer`), by name; None when not needed
    richer: dict | None = None

    def meaning(self) -> str:
        """The verdict and its consequences for a robot, in words a student can act on."""
        return explain(self)

    def summary_lines(self, sigma_method: str = "", width: int = 100) -> list[str]:
        """What the command line prints under the parameters: how sigma was computed, the consequences
        for a Duckiebot (one line) and :meth:`meaning` wrapped, each line indented by two spaces."""
        import textwrap

        out = [f"  +- is 1 sigma: {sigma_method}"] if sigma_method else []
        c = self.consequences
        if c:
            g = [f"{100 * r['ahead_m']:.0f} cm ahead +-{r['ground_sigma_cm']:.2g} cm" for r in c["ground"]
                 if r["ground_sigma_cm"] is not None]
            corner = "n/a" if c["corner_sigma_px"] is None else f"+-{c['corner_sigma_px']:.2f} px"
            out.append(f"  on a Duckiebot: ground point {', '.join(g) or 'outside the image'}; image corners {corner} "
                       f"(1 sigma, each known to +-{100 * c['relative_uncertainty']:.0f} %)")
        out += textwrap.wrap(self.meaning(), width, initial_indent="  ", subsequent_indent="  ")
        return out

    @property
    def noise_model(self) -> str:
        return (f"independent Gaussian corner noise, sigma {self.noise_sigma:.3f} px per coordinate, measured "
                f"model-free from {self.noise_points} interior corners against the quadratic through their "
                "8 grid neighbours")

    def warnings(self) -> list[str]:
        """One line per finding, each saying what to do; empty when the verdict is good."""
        return [f.warning() for f in self.findings]

    def views_to_drop(self) -> list[int]:
        out: set[int] = set()
        for f in self.findings:
            if f.code in ("outlier_views", "column_offset", "row_offset"):
                out.update(f.views)
        return sorted(out)

    def to_dict(self) -> dict:
        u = self.uncertainty
        return {
            "verdict": self.verdict,
            "findings": [f.to_dict() for f in self.findings],
            "warnings": self.warnings(),
            "noise_model": self.noise_model,
            "noise_sigma_px": float(self.noise_sigma),
            "fit_sigma_px": float(self.fit_sigma),
            "fit_to_noise": float(self.fit_sigma / max(self.noise_sigma, NOISE_FLOOR_PX)),
            "tilt_spread_deg": float(self.tilt_spread_deg),
            "projection_uncertainty": None if u is None else {
                "corner_sigma_px": None if np.isnan(u.corner_mean) else float(u.corner_mean),
                "per_corner_sigma_px": [float(s) for s in u.corner_sigma],
                "max_sigma_px": float(max(np.nanmax(u.sigma), np.nanmax(u.corner_sigma))),
                "unprojectable_share": float(np.isnan(u.sigma).mean()),
                "distance": float(u.distance),
                "worst_region": u.worst_region(),
            },
            "more_data_where": self.help_region,
            "notes": [n.to_dict() for n in self.notes],
            "richer_models": None if self.richer is None else {
                k: {"sigma_px": float(f.sigma), "rms_px": float(f.rms), "dist_terms": list(f.dist_names),
                    "warp_mm": [float(1000.0 * w) for w in f.warp]} for k, f in self.richer.items()},
            "consequences": self.consequences,
            "meaning": self.meaning(),
        }


def assess(result, evidence: Evidence, *, uncertainty: bool = True, distance: float | None = None) -> Quality:
    """Judge a calibration: verdict (``good`` / ``doubtful`` / ``bad``), findings with advice, uncertainty.

    Parameters
    ----------
    result : CalibrationResult (it carries its views)
    evidence : what the judge needs from the estimator (:func:`dtscal_lib.result.evidence`)
    uncertainty : also compute the projection-uncertainty map (a few hundred ms for 70 views)
    distance : distance of the fixed points of the uncertainty map (default: median board distance)

    Time and memory are linear in the views (4000 views of 35 corners: about 2 s and +89 MB on 2 busy cores).
    """
    try:
        case = run_rules(prepare(result, evidence, uncertainty=uncertainty, distance=distance))
    except MemoryError:
        raise CalibrationError(
            f"not enough memory to judge a calibration of {result.n_views} views ({result.n_points} corners, about "
            f"{result.n_points * 1.1e-6:.2f} GB needed); judge a calibration of fewer views") from None
    verdict = max((f.severity for f in case.findings), key=_SEVERITY.__getitem__, default="good")
    return Quality(verdict, case.findings, case.noise, case.n_noise, float(result.sigma),
                   np.asarray(result.per_view_rms), case.res, case.umap, case.counts, case.help_region,
                   evidence.tilt_spread_deg, consequences=case.cons, notes=case.notes,
                   without_outlier_corners=case.without_corners, richer=case.richer)


_VERDICT_WORDS = {
    "good": "good: the model explains the corners down to their noise, and the data pin the camera down.",
    "doubtful": "doubtful: usable, but something in the data or the model is not what the noise model assumes "
                "(the findings say what); the uncertainties stated here include it.",
    "bad": "bad: do not use this calibration on a robot; the findings say what to change.",
}


def explain(q: Quality) -> str:
    """The verdict, why, and what it means for a Duckiebot, as a few sentences (:meth:`Quality.meaning`)."""
    lines = [f"Verdict {_VERDICT_WORDS[q.verdict]}"]
    codes = {f.code for f in q.findings}
    if codes & {"fit", "board_warp", "unexplained_fit"} or q.notes:
        ratio = q.fit_sigma / max(q.noise_sigma, NOISE_FLOOR_PX)
        lines.append(
            f"The residuals are {ratio:.1f}x the corner noise measured in these very images: part of every residual "
            "is not noise but a pattern shared by neighbouring corners. More views of the same kind do not average "
            "it away; the standard deviations of the parameters are therefore measured from how much the views "
            "disagree with each other, not from the noise alone.")
        lines += [n.message[:1].upper() + n.message[1:] + "." for n in q.notes]
    c = q.consequences
    if c:
        m = c["mounting"]
        parts = []
        for g in c["ground"]:
            if g["ground_sigma_cm"] is None:
                parts.append(f"{100 * g['ahead_m']:.0f} cm ahead is outside this camera's image")
            else:
                parts.append(f"a point {100 * g['ahead_m']:.0f} cm ahead is placed within "
                             f"+-{g['ground_sigma_cm']:.2g} cm (1 sigma; {g['pixel_sigma_px']:.2g} px in the image)")
        rel = 100 * c["relative_uncertainty"]
        corner = ("cannot be stated (the lens model folds over there)" if c["corner_sigma_px"] is None
                  else f"is uncertain by {c['corner_sigma_px']:.2f} px (1 sigma)")
        lines.append(
            f"On a Duckiebot (camera {100 * m['height_m']:.0f} cm above the ground, {m['pitch_down_deg']:.0f} degrees "
            f"down), ground projection through these intrinsics: {'; '.join(parts)}. A pixel at the image corners "
            f"{corner}. These figures are themselves known to about +-{rel:.0f} % (from {q.per_view_rms.size} views). "
            "Lane detection projects the pixels of the road's markings onto the ground, so a pixel's error becomes "
            "centimetres that grow with the distance; the extrapolated image corners are where a lane marking seen "
            "at the side of the image is placed worst, and where more views (boards held there) help most.")
    return " ".join(lines)
