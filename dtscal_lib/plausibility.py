"""Would the kit itself believe this calibration? Checks run before a calibration file is written.

A calibration can converge, with a small residual, and still be wrong: forty copies of
one board image shifted around the picture fit a camera with fx = 186 where the truth
is 308. The optimiser cannot see that; these checks can. :func:`intrinsic_doubts` lists
what speaks against an intrinsic result; the ground homography's counterpart is
:func:`dtscal_lib.ground.ground_homography_doubts`. The pipeline refuses to write a
result with doubts (:class:`~dtscal_lib.errors.ImplausibleCalibrationError`, exit code 3
of ``dtscal``) unless the user keeps it anyway, beside the robot's file.

Each doubt is a :class:`~dtscal_lib.findings.Finding` (severity ``"bad"``: a refusal) whose
``str()`` is the message and what to do. The limits (:data:`INTRINSIC_LIMITS`) are rows of the one
table of belief, :mod:`dtscal_lib.limits`, each with its reason and data source; they are loose on
purpose: every real camera a course meets passes them, and a refusal always says what to do.
"""

from __future__ import annotations

import numpy as np

from .calibration import CalibrationResult, board_normal_spread
from .findings import Finding
from .limits import INTRINSIC_LIMITS

__all__ = ["INTRINSIC_LIMITS", "distinct_board_images", "intrinsic_doubts"]


def distinct_board_images(image_points, same_px: float = INTRINSIC_LIMITS["same_image_px"]) -> int:
    """How many views differ by more than a shift in the image.

    A board shifted in its own plane, facing the camera, or a picture of it pasted at
    another place in the frame, adds no information on the focal length; a tilted or
    turned board changes shape. Views are compared after removing their centroid; those
    within ``same_px`` rms of an earlier distinct view count as one. Views with a
    different number of points are always distinct. Linear in the number of views for
    a fixed number of distinct ones.

    >>> p = np.array([[0.0, 0], [10, 0], [0, 10], [12, 11]])
    >>> distinct_board_images([p, p + 50, p * 2])
    2
    """
    reps: list[np.ndarray] = []
    for p in image_points:
        c = np.asarray(p, dtype=np.float64).reshape(-1, 2)
        c = c - c.mean(axis=0)
        if not any(r.shape == c.shape and np.sqrt(np.mean(np.sum((r - c) ** 2, axis=1))) < same_px for r in reps):
            reps.append(c)
    return len(reps)


def intrinsic_doubts(result: CalibrationResult, image_points=None) -> list[Finding]:
    """Reasons not to believe an intrinsic calibration, as Findings; an empty list means plausible.

    Parameters
    ----------
    result : the calibration
    image_points : the views' (N_i, 2) pixels, for the shifted-copies check (optional)
    """
    lim = INTRINSIC_LIMITS
    K, (w, h) = np.asarray(result.K), result.image_size
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    out = []

    def doubt(code, message, advice, views=()):
        out.append(Finding(code, "bad", message, advice, list(views)))

    if image_points is not None:
        n = distinct_board_images(image_points)
        if n < lim["min_distinct_views"]:
            doubt("shifted_copies",
                  f"the {len(image_points)} views show only {n} distinct board image(s); the others are the "
                  "same image shifted in the picture, which says nothing about the focal length",
                  "tilt and turn the board between views")
    spread = board_normal_spread(result.rvecs)
    if spread < lim["min_tilt_spread_deg"]:
        doubt("parallel_views",
              f"the boards were tilted too little (normals within {spread:.1f} degrees of their mean; at least "
              f"{lim['min_tilt_spread_deg']:g} needed)", "tilt the board 20-45 degrees left/right and up/down")
    if result.rms > lim["max_rms_px"]:
        doubt("rms", f"the reprojection RMS is {result.rms:.2f} px (at most {lim['max_rms_px']:g})",
              "check --board and --square against the printed board, and that the board is flat and sharp in "
              "the frames")
    fov = float(np.degrees(2 * np.arctan2(w / 2.0, fx)))
    lo, hi = lim["fov_deg"]
    if not lo <= fov <= hi and lo / 2 <= fov:
        doubt("field_of_view",
              f"fx = {fx:.1f} px gives a {fov:.0f}-degree field of view across {w} px (plausible: {lo:g}-{hi:g})",
              "check --square and the image size, and recalibrate with tilted views")
    elif not lo <= fov <= hi:  # not a lens at all: the number itself would mislead, so it is not shown
        doubt("field_of_view",
              f"the focal length found describes no camera (a field of view far below {lo:g} degrees): the views "
              "do not fit the declared board",
              "check --board (count the inner corners) and --square against the printed board, and recalibrate "
              "with tilted views")
    lo, hi = lim["aspect"]
    if not lo <= fx / fy <= hi:
        doubt("aspect", f"fx / fy = {fx / fy:.2f} (a camera with square pixels has about 1; plausible {lo:g}-{hi:g})",
              "recalibrate with views tilted both left/right and up/down")
    off = max(abs(cx - (w - 1) / 2.0) / w, abs(cy - (h - 1) / 2.0) / h)
    if off > lim["max_centre_offset"]:
        doubt("principal_point",
              f"the principal point ({cx:.1f}, {cy:.1f}) lies {100 * off:.0f}% of the image from its centre "
              f"(at most {100 * lim['max_centre_offset']:.0f}%)", "add views with the board near the image corners")
    rel = max(result.std.get("fx", 0.0) / fx, result.std.get("fy", 0.0) / fy)
    if not rel <= lim["max_relative_focal_std"]:
        doubt("focal_std",
              f"the focal length is determined only to +-{100 * rel:.1f}% (at most "
              f"{100 * lim['max_relative_focal_std']:g}%)", "add views with the board tilted and near the image "
              "corners")
    return out
