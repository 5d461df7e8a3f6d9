"""The verdict's rules: each a named check of a calibration, run in a fixed order (:data:`RULES`).

A rule reads a :class:`Case` -- the result, what the judge was given (:class:`~dtscal_lib.findings.Evidence`),
the residuals, the corner noise measured without a model, the projection uncertainty and what it means
for the robot -- and adds :class:`~dtscal_lib.findings.Finding` s (or notes, which do not change the
verdict). A later rule may read what an earlier one found (a bent column explains the residual: the fit
rule's finding becomes a note; far-off corners are then its echo, not outliers). Messages are written
once, by the rule that finds them.

"Bad" follows the robot's cost (:func:`_robot_cost`): a finding is bad when the calibration would mislead
the robot where it looks (:func:`dtscal_lib.uncertainty.robot_view`), measured as projection error there in
pixels; the uncertainty at image corners no board reached is advice (hold the board there), never bad.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import cv2
import numpy as np

from .camera import KIT_SOLVER_MODELS, CameraModel, project_points
from .errors import DtscalError
from .findings import Evidence, Finding
from .limits import (
    CORNER_SIGMA_DOUBTFUL,
    FIT_RATIO_BAD,
    FIT_RATIO_DOUBTFUL,
    LENS_SHARE,
    MIN_GOOD_VIEWS,
    NEIGHBOUR_CORRELATION,
    OFFSET_VIEW_SHARE,
    OFFSET_Z,
    OUTLIER_CORNER_MAX_SHARE,
    OUTLIER_CORNER_MIN_PX,
    OUTLIER_CORNER_Z,
    RADIAL_FRACTION,
    RADIAL_Z,
    ROBOT_SHIFT_BAD_PX,
    ROBOT_VIEW_SIGMA_BAD,
    ROBOT_VIEW_SIGMA_DOUBTFUL,
    SYSTEMATIC_RATIO_BAD,
    TILT_BAD_DEG,
    TILT_DOUBTFUL_DEG,
    UNEXPLAINED_RATIO_BAD,
    UNEXPLAINED_RATIO_DOUBTFUL,
    VIEW_OUTLIER_FACTOR,
)
from .uncertainty import (
    REGION_NAMES,
    UncertaintyMap,
    _need_observations,
    _projection_jacobian,
    _uncertainty_inputs,
    consequences,
    image_region,
    robot_view,
    robot_view_sigma,
    uncertainty_map,
)
from .covariance import rodrigues

__all__ = ["Case", "RULES", "run_rules", "residuals", "residuals_of", "grid_indices", "corner_noise",
           "leave_out_outlier_corners", "robot_view_shift", "NOISE_FLOOR_PX"]

#: the fewest views in which a board warp is named (mrcal's two warp terms; below, 3 views leave the warp and the
#: poses to trade off). Measured: a 1.5 mm / -0.8 mm warp is recovered to 0.01 mm from 4 and 5 synthetic views
#: (tests/test_verdict_real.py checks it); OpenCV's real photographs, 25 random 4-5-view subsets per camera, name
#: a warp (doubtful, never bad) in 2 (left) and 3 (right): a real print is not perfectly flat either
MIN_WARP_VIEWS = 4
#: a step between two grid lines of one view is named above this many standard errors and this many times the
#: corner noise. Measured on OpenCV's real photographs (benchmarks/bench_verdict_subsets.py prints it): clean
#: views reach 6.8 (left) and 4.8 (right); a lower half shifted by 0.3 px stands at 4.7-8.5, by 0.5 px at 8.9-12.8
SEAM_Z = 8.0
SEAM_NOISE_FACTOR = 3.0
#: no detector measures corners of an 8-bit image much better than this (pixels, per coordinate);
#: the noise used in the ratios never goes below it (exact synthetic points would divide by 0)
NOISE_FLOOR_PX = 0.01


# =========================================================================== residuals and grid
def residuals(result) -> list[np.ndarray]:
    """Per view (N_i, 2) ``projected - observed`` pixels of a result that carries its observations."""
    _need_observations(result)
    return residuals_of(result, result.object_points, result.image_points)


def _camera_points(fit, obj_list):
    """``(counts, Rv, P)``: the points per view, each point's view rotation (M, 3, 3) and the board points in the
    camera frame (M, 3) through a fit's poses, all views stacked."""
    counts = [len(o) for o in obj_list]
    view = np.repeat(np.arange(len(obj_list)), counts)
    xy = np.concatenate([np.asarray(o, dtype=np.float64)[:, :2] for o in obj_list])
    R, _ = rodrigues(np.asarray(fit.rvecs, dtype=np.float64), jacobian=False)
    Rv = R[view]
    return counts, Rv, Rv[:, :, 0] * xy[:, :1] + Rv[:, :, 1] * xy[:, 1:] + np.asarray(fit.tvecs, dtype=np.float64)[view]


def residuals_of(fit, obj_list, img_list) -> list[np.ndarray]:
    """Per view (N_i, 2) ``projected - observed`` pixels of board points ``obj_list`` seen at ``img_list``
    through a fit's camera and poses (all views in one projection; skew honoured)."""
    counts, _, P = _camera_points(fit, obj_list)
    q = project_points(P, np.zeros(3), np.zeros(3), fit.K, fit.dist, model=getattr(fit, "model", "plumb_bob"))
    obs = np.concatenate([np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in img_list])
    return np.split(q - obs, np.cumsum(counts)[:-1])


def grid_indices(obj: np.ndarray) -> np.ndarray:
    """(N, 2) int (column, row) of each board-plane point of a regular grid, from its coordinates.

    Columns are the distinct x values in increasing order, rows the distinct y values.
    """
    obj = np.asarray(obj, dtype=np.float64)[:, :2]
    out = np.zeros((len(obj), 2), dtype=int)
    for k in range(2):
        x = obj[:, k]
        steps = np.diff(np.unique(x))
        tol = 1e-6 * max(float(np.ptp(x)), 1e-12)
        pitch = steps[steps > tol].min() if np.any(steps > tol) else 1.0
        out[:, k] = np.rint((x - x.min()) / pitch).astype(int)
    return out


# offsets of the 8 neighbours and the weights of the least-squares quadratic through them at (0, 0)
_RING = np.array([(dc, dr) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if (dc, dr) != (0, 0)], dtype=float)
_RING_W = np.linalg.pinv(np.column_stack([np.ones(8), _RING[:, 0], _RING[:, 1], _RING[:, 0] ** 2,
                                          _RING[:, 0] * _RING[:, 1], _RING[:, 1] ** 2]))[0]
_RING_GAIN = float(np.sqrt(1.0 + (_RING_W ** 2).sum()))  # std of (observed - predicted) / sigma


def _grid_groups(object_points) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Views that show the same points of the same grid, so that their checks run on stacked arrays.

    Returns ``[(views, obj (N, 2), grid (N, 2) int)]``, every view in exactly one group.
    """
    groups: dict[bytes, list] = {}
    for v, o in enumerate(object_points):
        o = np.ascontiguousarray(np.asarray(o, dtype=np.float64)[:, :2])
        groups.setdefault(o.tobytes() + bytes(str(o.shape), "ascii"), [o, []])[1].append(v)
    return [(np.asarray(views), o, grid_indices(o)) for o, views in groups.values()]


def _ring_neighbours(g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Interior corners of a grid (all 8 neighbours present): their indices (M,) and the neighbours' (M, 8)."""
    lookup = {(int(c), int(r)): i for i, (c, r) in enumerate(g)}
    idx, nbs = [], []
    for i, (c, r) in enumerate(g):
        nb = [lookup.get((int(c + dc), int(r + dr))) for dc, dr in _RING.astype(int)]
        if all(n is not None for n in nb):
            idx.append(i)
            nbs.append(nb)
    return np.asarray(idx, dtype=int), np.asarray(nbs, dtype=int).reshape(-1, 8)


def corner_noise(object_points, image_points) -> tuple[float, int]:
    """Model-free corner noise of a set of views: ``(sigma per coordinate in pixels, corners used)``.

    Each interior corner (all 8 grid neighbours detected) is predicted by the least-squares
    quadratic in grid coordinates through its neighbours; ``sigma = 1.4826 * median|error| / g`` with
    ``g = sqrt(1 + sum w^2)`` the prediction's noise gain, so a few corners pulled off by clutter do
    not inflate it. Returns ``(nan, 0)`` when no view has an interior corner.
    """
    errs = []
    for views, _, g in _grid_groups(object_points):
        idx, nb = _ring_neighbours(g)
        if len(idx):
            p = np.stack([np.asarray(image_points[v], dtype=np.float64).reshape(-1, 2) for v in views])
            errs.append((p[:, idx] - np.einsum("k,vmkc->vmc", _RING_W, p[:, nb])).reshape(-1, 2))
    e = np.concatenate(errs) if errs else np.zeros((0, 2))
    if len(e) == 0:
        return float("nan"), 0
    return float(1.4826 * np.median(np.abs(e)) / _RING_GAIN), len(e)


def _board_axis_jacobians(fit, obj_list, dist_idx) -> list[np.ndarray]:
    """Per view (N_i, 2, 2) ``d pixel / d (board x, board y)`` at each board point, through the fitted camera."""
    counts, Rv, P = _camera_points(fit, obj_list)
    _, dqdP, _ = _projection_jacobian(P, fit.K, fit.dist, fit.skew, dist_idx)
    return np.split(np.matmul(dqdP, Rv[:, :, :2]), np.cumsum(counts)[:-1])


def _board_axis_components(J: np.ndarray, res: np.ndarray) -> np.ndarray:
    """Residuals (..., 2) resolved along the board's x and y axes as seen in the image, in pixels.

    ``J`` (..., 2, 2) is ``d pixel / d board`` at each point (:func:`_board_axis_jacobians`).
    """
    b = np.linalg.solve(J, res[..., None])[..., 0]  # board-plane displacement
    return b * np.linalg.norm(J, axis=-2)  # back to pixels along each axis


def _line_means(obj_list, comps):
    """``{(axis, line): (views, mean offsets, points on the line)}``: per grid column (axis 0) / row (axis 1),
    the mean of the board-axis residual components of its corners in each view (stacked per grid)."""
    out: dict[tuple[int, int], list] = {}
    for views, _, g in _grid_groups(obj_list):
        c = np.stack([comps[v] for v in views])  # (G, N, 2)
        for axis in (0, 1):
            for line in np.unique(g[:, axis]):
                sel = g[:, axis] == line
                out.setdefault((axis, int(line)), []).append((views, c[:, sel, axis].mean(axis=1), int(sel.sum())))
    return out


def _line_offsets(fit, obj_list, res, noise, dist_idx) -> dict[tuple[int, int], dict[int, float]]:
    """``{(axis, line): {view: mean offset px}}`` for the grid columns (axis 0) and rows (axis 1) whose
    residuals along the board's axis share one offset in at least ``OFFSET_VIEW_SHARE`` of the views."""
    comps = [_board_axis_components(J, e) for J, e in zip(_board_axis_jacobians(fit, obj_list, dist_idx), res)]
    offsets: dict[tuple[int, int], dict[int, float]] = {}
    for key, parts in _line_means(obj_list, comps).items():
        for views, m, count in parts:
            hit = np.abs(m) > max(OFFSET_Z * noise / np.sqrt(count), noise)
            for v, val in zip(views[hit], m[hit]):
                offsets.setdefault(key, {})[int(v)] = float(val)
    return {k: d for k, d in offsets.items() if len(d) >= max(2, OFFSET_VIEW_SHARE * len(res))}


def _without_line(refit, obj_list, img_list, axis: int, line: int, dist_idx):
    """Re-calibrate without one grid column/row; returns the fit and, per view, that line's mean offset."""
    keep = [grid_indices(o)[:, axis] != line for o in obj_list]
    try:
        fit = refit([o[k] for o, k in zip(obj_list, keep)], [p[k] for p, k in zip(img_list, keep)])
    except (DtscalError, cv2.error, np.linalg.LinAlgError):  # e.g. too few points left in a view
        return None, None
    res = residuals_of(fit, obj_list, img_list)
    comps = [_board_axis_components(J, e) for J, e in zip(_board_axis_jacobians(fit, obj_list, dist_idx), res)]
    means = np.array([float(c[~k, axis].mean()) for c, k in zip(comps, keep)])
    return fit, means


def _offset_findings(refit, result, obj_list, img_list, res, noise, dist_idx, rounds: int = 2) -> list[Finding]:
    """Columns or rows of corners offset the same way in many views, located by leaving each suspect out.

    The residuals of the full fit smear one bad column over its neighbours (the camera absorbs part
    of it), so every flagged line is left out in turn; the one whose removal lowers the fit's sigma
    most is the cause, and its offsets against that fit name the views. Repeated once more for a
    second bad line.
    """
    out = []
    names = ("column", "row")
    first = result
    for _ in range(rounds):
        flagged = _line_offsets(result, obj_list, res, noise, dist_idx)
        if not flagged:
            break
        size = {k: float(np.median(np.abs(list(d.values())))) for k, d in flagged.items()}
        top = max(size.values())
        best = None
        for axis, line in [k for k in flagged if size[k] >= 0.5 * top]:  # the strongest suspects only
            fit, means = _without_line(refit, obj_list, img_list, axis, line, dist_idx)
            if fit is not None and (best is None or fit.sigma < best[2].sigma):
                best = (axis, line, fit, means)
        if best is None:
            break
        axis, line, fit, means = best
        n_line = int(np.sum(grid_indices(obj_list[0])[:, axis] == line))
        off = np.abs(means) > max(OFFSET_Z * noise / np.sqrt(n_line), noise)
        if not off.any():
            break
        sign = np.sign(np.median(means[off]))
        consistent = float(np.mean(np.sign(means[off]) == sign))
        excess_drop = 1.0 - (fit.sigma ** 2 - noise ** 2) / max(result.sigma ** 2 - noise ** 2, 1e-300)
        views = [int(v) for v in np.flatnonzero(off & (np.sign(means) == sign))]
        # a pulled detector shifts the line the same way (towards the board's edge) in every view and
        # leaving it out explains the data; a lens the model cannot follow shifts it one way or the
        # other depending on where the board is, and leaving it out only helps a little
        explained = fit.sigma <= FIT_RATIO_DOUBTFUL * noise or (consistent >= 0.9 and excess_drop >= 0.75)
        if len(views) < max(2, OFFSET_VIEW_SHARE * len(res)) or not explained:
            break
        name = names[axis]
        size = float(np.median(np.abs(means[views])))
        shift = robot_view_shift(first, fit)
        severity, cost = _robot_cost(shift, first.image_size)
        redetect = (f"re-detect with a corner refinement that stays within each corner's own four squares; look "
                    f"at {name} {line} on those images")
        if severity != "bad":  # the robot does not notice it: nothing to drop
            advice = f"nothing to do for the robot; to remove it, {redetect}"
        elif 2 * len(views) > len(res):  # most views: the print or the detector, not a few frames
            advice = f"{redetect}, or check the printed board's {name} {line} (flat, the squares the size given)"
        else:
            advice = f"drop views {_list(views)} or {redetect}"
        out.append(Finding(
            f"{name}_offset", severity,
            f"{name} {line} of the board's corners is offset by {size:.2f} px (median) along the board's "
            f"{'xy'[axis]} axis in {len(views)} of {len(res)} views (views {_list(views)}); without that {name} "
            f"the residual sigma drops from {result.sigma:.3f} to {fit.sigma:.3f} px. The same corners are "
            "wrong the same way view after view: the detector was pulled (by the board's edge, a printed "
            f"outline or clutter), this is not noise. {cost}", advice, views))
        # look for a second bad line in the fit without this one
        keep = [grid_indices(o)[:, axis] != line for o in obj_list]
        obj_list = [o[k] for o, k in zip(obj_list, keep)]
        img_list = [p[k] for p, k in zip(img_list, keep)]
        res = residuals_of(fit, obj_list, img_list)
        result = fit
    return out


def _radial_finding(result, res, noise, lens_words: str = "") -> Finding | None:
    """A radial residual that depends on the distance from the principal point: the lens model is too simple."""
    c = np.array([result.K[0, 2], result.K[1, 2]])
    pts = np.concatenate([np.asarray(p).reshape(-1, 2) for p in result.image_points])
    e = np.concatenate(res)
    d = pts - c
    r = np.linalg.norm(d, axis=1)
    if len(r) < 40:
        return None
    radial = np.einsum("ij,ij->i", e, d / np.maximum(r, 1e-9)[:, None])
    edges = np.quantile(r, np.linspace(0, 1, 9))
    band = np.clip(np.searchsorted(edges, r, side="right") - 1, 0, 7)
    worst = None
    for b in range(8):
        sel = band == b
        m = float(radial[sel].mean())
        if abs(m) > max(RADIAL_Z * noise / np.sqrt(sel.sum()), RADIAL_FRACTION * noise):
            if worst is None or abs(m) > abs(worst[0]):
                worst = (m, edges[b], edges[b + 1])
    if worst is None:
        return None
    m, r0, r1 = worst
    cause = ("a radial pattern that finer lens models fitted to the same corners do not remove (the print or the "
             "detector)" if lens_words.startswith("not the lens model")
             else f"a radial pattern the {result.model} distortion model cannot absorb")
    advice = "show the board in the image corners, where distortion is strongest"
    return Finding("radial", "bad" if abs(m) > 2 * noise else "doubtful",
                   f"corners {r0:.0f}-{r1:.0f} px from the principal point are off by {m:+.2f} px radially on "
                   f"average (corner noise {noise:.3f} px): {cause}",
                   f"{lens_words}; {advice}" if lens_words else advice)


def _richer_model(result, noise: float, fits: dict | None) -> str:
    """Advice about the lens model, from the richer models actually fitted (:func:`_richer_fits`)."""
    if result.model == "equidistant":  # calibrated by OpenCV's fisheye module: no finer model is fitted
        return "use --model rational_polynomial (the fisheye model has no tangential terms), or check the board"
    if result.model == "rational_polynomial":
        return "the richest of ROS's models already: check the board's flatness and the detections"
    fits = _richer_fits(result, noise) if fits is None else fits
    lens = {k: f for k, f in fits.items() if k != "warp"}
    name, share = _best_lens(result, noise, lens)
    if name is not None and share >= LENS_SHARE:
        return f"{_LENS_ADVICE[name]}: fitted, it explains {100 * share:.0f} % of the residual above the noise"
    tried = ", ".join(_LENS_WORDS[k] for k in lens)
    return (f"not the lens model: {tried} fitted to these corners explain{'s' if len(lens) == 1 else ''} only "
            f"{100 * max(share, 0.0):.0f} % of the residual above the noise")


#: the lens candidates in words (the finding's message) and as advice
_LENS_WORDS = {"k3": "k3", "rational": "OpenCV's 8-coefficient rational model", "tangential": "tangential terms"}
_LENS_ADVICE = {"k3": "estimate k3 as well (dtscal_lib.calibration.calibrate(..., fix_k3=False); ROS keeps k3 = 0)",
                "rational": "use a richer lens model, OpenCV's 8-coefficient rational (not in ROS's camera_info: use "
                            "a lens with less distortion or keep to the well-modelled centre)",
                "tangential": "use --model plumb_bob (radial2 has no tangential terms)"}


def _richer_fits(result, noise: float | None = None) -> dict:
    """The finer lens models and the board warp fitted to a result's own corners (:mod:`dtscal_lib.richer`).

    The rational model holds every other lens candidate (k3, tangential terms), so they are fitted only when
    it explains at least :data:`LENS_SHARE` of the residual above ``noise`` (to name the smallest model that
    does): the common case costs two fits (``benchmarks/bench_calibrate.py``).
    """
    from .richer import candidates, excess_share, fit_richer

    if result.model not in ("plumb_bob", "radial2"):  # OpenCV's rational and fisheye results: nothing finer here
        return {}
    def fit(name):
        try:
            out[name] = fit_richer(result, name)
        except (cv2.error, np.linalg.LinAlgError, ValueError):
            pass

    out: dict = {}
    fit("rational")
    fit("warp")
    rational = out.get("rational")
    if noise is None or rational is None or excess_share(result.sigma, rational.sigma, noise) >= LENS_SHARE:
        for name in candidates(result):
            if name not in out:
                fit(name)
    return out


def _best_lens(result, noise, lens: dict) -> tuple[str | None, float]:
    """The lens candidate to name: the one with fewest parameters among those explaining at least
    :data:`LENS_SHARE` of the residual above the noise (k3 before the rational model: ROS's files hold k3),
    else the one explaining most."""
    from .richer import excess_share
    shares = {k: excess_share(result.sigma, f.sigma, noise) for k, f in lens.items()}
    enough = [k for k, v in shares.items() if v >= LENS_SHARE]
    if enough:
        k = min(enough, key=lambda n: (lens[n].n_params, -shares[n]))
        return k, shares[k]
    k = max(shares, key=shares.get, default=None)
    return (k, shares[k]) if k is not None and shares[k] > 0 else (None, 0.0)


def _fit_findings(result, noise: float, cost: str = ""):
    """The residual against the corner noise: who explains it.

    Returns ``(findings, notes, fits)``. Below :data:`FIT_RATIO_DOUBTFUL` nothing is fitted. Above it the
    finer lens models and mrcal's board warp are fitted (:mod:`dtscal_lib.richer`); the lens model is blamed
    (finding ``fit``, with the model to use) only when one explains at least :data:`LENS_SHARE` of the
    residual above the noise; a board warp that does is named with its size in mm (``board_warp``);
    otherwise the residual is the print and the detector's (a note, in words, with what it costs on the
    ground), and only beyond :data:`UNEXPLAINED_RATIO_DOUBTFUL` / :data:`UNEXPLAINED_RATIO_BAD` does it
    change the verdict.
    """
    from .richer import excess_share
    ratio = result.sigma / noise
    if not ratio > FIT_RATIO_DOUBTFUL:
        return [], [], None
    fits = _richer_fits(result, noise)
    lens = {k: f for k, f in fits.items() if k != "warp"}
    name, share = _best_lens(result, noise, lens)
    warp = fits.get("warp")
    wshare = excess_share(result.sigma, warp.sigma, noise) if warp is not None else 0.0
    head = (f"the residuals (sigma {result.sigma:.3f} px per coordinate, RMS {result.rms:.3f} px) are {ratio:.1f} "
            f"times the corner noise of these images ({noise:.3f} px, measured without a model)")
    findings, notes = [], []
    if name is not None and share >= LENS_SHARE and share >= wshare:
        f = lens[name]
        findings.append(Finding(
            "fit", "bad" if ratio > FIT_RATIO_BAD else "doubtful",
            f"{head}; {_LENS_WORDS[name]} brings sigma to {f.sigma:.3f} px ({100 * share:.0f} % of the residual "
            f"above the noise): the {result.model} model does not follow this lens{cost}",
            _LENS_ADVICE[name]))
        return findings, notes, fits
    warp_words = ""
    if warp is not None:
        mm = 1000.0 * warp.warp  # the board's unit is metres (dtscal_lib.boards)
        warp_words = (f"a board warp as mrcal fits it (the middle of the board {mm[0]:+.2f} mm along its x axis, "
                      f"{mm[1]:+.2f} mm along y, out of its plane) brings sigma to {warp.sigma:.3f} px "
                      f"({100 * wshare:.0f} % of the excess)")
    lens_words = (f"{' and '.join(_LENS_WORDS[k] for k in lens)} explain{'s' if len(lens) == 1 else ''} "
                  f"{'at most ' if len(lens) > 1 else ''}{100 * share:.0f} %" if lens
                  else "no finer lens model could be fitted")
    if warp is not None and wshare >= LENS_SHARE and result.n_views >= MIN_WARP_VIEWS:
        findings.append(Finding(
            "board_warp", "bad" if ratio > UNEXPLAINED_RATIO_BAD else "doubtful",
            f"{head}; the board is not flat: {warp_words}; {lens_words} of the excess{cost}",
            "glue the printed board to a flat, rigid plate (glass, aluminium, thick acrylic) and calibrate again"))
        return findings, notes, fits
    excess = float(np.sqrt(max(result.sigma ** 2 - noise ** 2, 0.0)))
    text = (f"{head}: {excess:.3f} px per coordinate is neither noise nor the lens model "
            f"(fitted to these corners, {lens_words} of the excess{'; ' + warp_words if warp_words else ''}): "
            f"it is the print and the detector (corners pulled the same way in neighbouring corners){cost}")
    if ratio > UNEXPLAINED_RATIO_DOUBTFUL:
        findings.append(Finding(
            "unexplained_fit", "bad" if ratio > UNEXPLAINED_RATIO_BAD else "doubtful", text,
            "look at the residual figures (dtscal calibrate-intrinsics --report DIR): a blurred or mis-detected "
            "board, a board that moved during exposure, or a wrong square count"))
    else:
        notes.append(Finding("unexplained_fit", "good", text, ""))
    return findings, notes, fits


def _outlier_corners(refit, result, obj_list, img_list, res):
    """Single corners far off where the camera puts them: found, named, left out, the calibration repeated.

    A corner is an outlier when its residual (a 2-D vector) is longer than :data:`OUTLIER_CORNER_Z` robust
    standard deviations of the residual coordinates (``1.4826 * median |e|``) and than
    :data:`OUTLIER_CORNER_MIN_PX`. Returns ``(finding, refit)``
    or ``(None, None)``; more than :data:`OUTLIER_CORNER_MAX_SHARE` of the corners at once is not a few bad
    corners but a pattern (the other rules say which).
    """
    e = np.concatenate(res)
    scale = 1.4826 * float(np.median(np.abs(e)))
    if not scale > 0:
        return None, None, []
    limit = max(OUTLIER_CORNER_Z * scale, OUTLIER_CORNER_MIN_PX)
    hits = [(v, int(i), float(np.linalg.norm(r[i]))) for v, r in enumerate(res)
            for i in np.flatnonzero(np.linalg.norm(r, axis=1) > limit)]
    if not hits or len(hits) > max(1, OUTLIER_CORNER_MAX_SHARE * len(e)):
        return None, None, []
    keep = [np.ones(len(o), dtype=bool) for o in obj_list]
    for v, i, _ in hits:
        keep[v][i] = False
    try:
        fit = refit([o[k] for o, k in zip(obj_list, keep)], [p[k] for p, k in zip(img_list, keep)])
    except (DtscalError, cv2.error, np.linalg.LinAlgError):
        return None, None, []
    left = []
    for v, i, size in hits:
        c, r = grid_indices(obj_list[v])[i]
        left.append({"view": int(v), "corner": int(i), "column": int(c), "row": int(r), "residual_px": float(size),
                     "robust_sigmas": float(size / scale)})
    names = [_corner_words(h) for h in left[:6]]
    more = f" ... ({len(hits)} in all)" if len(hits) > 6 else ""
    df = fit.K[0, 0] - result.K[0, 0]
    return Finding(
        "outlier_corners", "doubtful",
        f"{len(hits)} corner(s) lie far from where the camera puts them ({'; '.join(names)}{more}; the limit is "
        f"{limit:.2f} px: {OUTLIER_CORNER_Z:g} x {scale:.3f} px, the residuals' robust sigma, and at least "
        f"{OUTLIER_CORNER_MIN_PX:g} px). Calibrated again without "
        f"{'it' if len(hits) == 1 else 'them'}: RMS {result.rms:.3f} -> {fit.rms:.3f} px, fx {df:+.2f} px",
        "use the calibration without these corners (shown above) or re-detect those views: a corner the "
        "detector put on clutter, a reflection or the board's edge", sorted({v for v, _, _ in hits})), fit, left


def _corner_words(h: dict) -> str:
    return (f"view {h['view']} corner {h['corner']} (column {h['column']}, row {h['row']}): {h['residual_px']:.2f} px, "
            f"{h['robust_sigmas']:.0f} sigma")


def leave_out_outlier_corners(result, evidence: Evidence):
    """``result`` calibrated again without its outlier corners (``left_out_corners`` names them), or ``result``.

    What ``dtscal calibrate-intrinsics`` and the live CALIBRATE do after dropping outlier views
    (:func:`dtscal_lib.session.calibrate_without_outlier_views`). Nothing is left out when the far-off corners
    are the echo of something else: a column or row offset in many views (:func:`_offset_findings`) or a lens the
    model cannot follow (a finer lens model, fitted, explains the residual: :func:`_fit_findings`).
    """
    obj = [np.asarray(o, float)[:, :2] for o in result.object_points]
    img = [np.asarray(p, float).reshape(-1, 2) for p in result.image_points]
    res = residuals(result)
    finding, fit, left = _outlier_corners(evidence.refit, result, obj, img, res)
    if fit is None:
        return result
    noise_raw, _ = corner_noise(obj, img)
    noise = max(noise_raw, NOISE_FLOOR_PX) if np.isfinite(noise_raw) else max(result.sigma, NOISE_FLOOR_PX)
    if (any(f.code == "fit" for f in _fit_findings(result, noise)[0])
            or _offset_findings(evidence.refit, result, obj, img, res, noise, evidence.dist_indices)):
        return result
    fit.left_out_corners = list(result.left_out_corners) + left
    return fit


def _neighbour_correlation(obj_list, res) -> float:
    """Mean normalised dot product of the residual vectors of grid-neighbouring corners (0 for noise)."""
    num = den = 0.0
    for views, _, g in _grid_groups(obj_list):
        e = np.stack([res[v] for v in views])  # (G, N, 2)
        lookup = {(int(a), int(b)): i for i, (a, b) in enumerate(g)}
        pairs = np.array([(i, j) for i, (a, b) in enumerate(g) for da, db in ((1, 0), (0, 1))
                          if (j := lookup.get((int(a + da), int(b + db)))) is not None], dtype=int).reshape(-1, 2)
        if len(pairs):
            ei, ej = e[:, pairs[:, 0]], e[:, pairs[:, 1]]
            num += float(np.einsum("vpc,vpc->", ei, ej))
            den += 0.5 * float(np.einsum("vpc,vpc->", ei, ei) + np.einsum("vpc,vpc->", ej, ej))
    return num / den if den > 0 else 0.0


def _list(views) -> str:
    views = [int(v) for v in views]
    return ", ".join(map(str, views[:12])) + (f" ... ({len(views)} in all)" if len(views) > 12 else "")


def _ground_cost(result, noise, cons) -> str:
    """The residual that is not noise, carried onto the ground as the consequences' pixels are."""
    excess = float(np.sqrt(max(result.sigma ** 2 - noise ** 2, 0.0)))
    parts = [f"{100 * g['ahead_m']:.0f} cm ahead {excess * g['ground_sigma_cm'] / g['pixel_sigma_px']:.2g} cm"
             for g in cons["ground"] if g["ground_sigma_cm"] and g["pixel_sigma_px"]]
    if not parts:
        return ""
    return (f". On a Duckiebot a pixel error of that size moves a ground point {', '.join(parts)}")



# =========================================================================== the robot's cost
def _camera_of(fit) -> CameraModel:
    return CameraModel(fit.K, fit.dist, fit.image_size, getattr(fit, "model", "plumb_bob"))


def robot_view_shift(a, b) -> float:
    """How far calibration ``b`` moves the projection against ``a`` where the robot looks: the mean projection
    difference (mrcal's ``projection_diff``, :func:`dtscal_lib.compare.projection_difference`, points at
    infinity, the rotation fitted near the centre) over :func:`~dtscal_lib.uncertainty.robot_view`, pixels."""
    from .compare import projection_difference

    comp = projection_difference(_camera_of(a), _camera_of(b), gridn_width=32, uncertainty=False)
    sel = robot_view(comp.pixels.reshape(-1, 2), a.image_size)
    d = comp.diff.ravel()[sel]
    return float(np.nanmean(d)) if np.isfinite(d).any() else float("inf")


def _robot_cost(shift_px: float, image_size) -> tuple[str, str]:
    """Severity and words of a defect whose removal moves the projection where the robot looks by ``shift_px``."""
    w, h = image_size
    where = "the DD24's view" if h > w else "the lower half of the image, the ground ahead of a Duckiebot"
    words = (f"Leaving it out moves the projection where the robot looks ({where}) by {shift_px:.2f} px on "
             f"average (bad above {ROBOT_SHIFT_BAD_PX:g} px)")
    return ("bad" if shift_px > ROBOT_SHIFT_BAD_PX else "doubtful"), words


# =========================================================================== the rules, in order
@dataclass
class Case:
    """What the rules read, and what they found so far."""

    result: Any
    evidence: Evidence
    obj: list
    img: list
    res: list
    noise: float
    n_noise: int
    umap: UncertaintyMap | None
    cov: Any
    cons: dict | None
    counts: np.ndarray
    help_region: str
    findings: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    richer: dict | None = None
    lines: list = field(default_factory=list)
    corner_finding: Finding | None = None
    without_corners: Any = None
    fit_blamed: bool = False

    @property
    def ratio(self) -> float:
        return float(self.result.sigma / self.noise)


def prepare(result, evidence: Evidence, *, uncertainty: bool = True, distance: float | None = None) -> Case:
    """The residuals, the model-free corner noise, the projection uncertainty and its consequences."""
    _need_observations(result)
    obj = [np.asarray(o, float)[:, :2] for o in result.object_points]
    img = [np.asarray(p, float).reshape(-1, 2) for p in result.image_points]
    res = residuals(result)
    noise_raw, n_noise = corner_noise(obj, img)
    noise = max(noise_raw, NOISE_FLOOR_PX) if np.isfinite(noise_raw) else max(result.sigma, NOISE_FLOOR_PX)
    ri, ci = image_region(np.concatenate(img), result.image_size)
    counts = np.zeros((3, 3), dtype=int)
    np.add.at(counts, (ri, ci), 1)
    umap = cov = cons = None
    # the projection uncertainty propagates the kit's own solver's normal equations; OpenCV's models have none
    if uncertainty and result.model in KIT_SOLVER_MODELS and evidence.blocks is not None:
        try:
            cov = _uncertainty_inputs(evidence.blocks)
            umap = uncertainty_map(result, distance=distance, cov=cov, dist_idx=evidence.dist_indices)
        except np.linalg.LinAlgError:
            umap = None
    if umap is not None:
        help_region = umap.worst_region()
        try:
            cons = consequences(result, umap=umap, cov=cov, dist_idx=evidence.dist_indices)
        except (np.linalg.LinAlgError, DtscalError):
            cons = None
    else:
        r, c = np.unravel_index(int(np.argmin(counts)), counts.shape)
        help_region = REGION_NAMES[r][c]
    return Case(result, evidence, obj, img, res, float(noise), n_noise, umap, cov, cons, counts, help_region)


def rule_converged(c: Case) -> None:
    """A refinement stopped at its iteration cap, not at the minimum: nothing else it says can be trusted."""
    if not getattr(c.result, "converged", True):
        c.findings.append(Finding(
            "not_converged", "bad",
            f"the refinement stopped after {c.result.iterations} iterations without converging: the camera is not "
            "at the minimum of the reprojection error",
            "collect more varied views (tilted boards filling the image) and calibrate again"))


def rule_fit(c: Case) -> None:
    """The residual against the corner noise, and who explains it (a finer lens model, a board warp, or the
    print and the detector), with what it costs on the ground."""
    cost = _ground_cost(c.result, c.noise, c.cons) if c.cons is not None else ""
    found, notes, c.richer = _fit_findings(c.result, c.noise, cost)
    c.findings += found
    c.notes += notes
    c.fit_blamed = any(f.code == "fit" for f in found)


def rule_outlier_views(c: Case) -> None:
    """Views whose own RMS is far above the others', named."""
    pv = np.asarray(c.result.per_view_rms)
    limit = VIEW_OUTLIER_FACTOR * float(np.median(pv))
    bad_views = [int(v) for v in np.flatnonzero((pv > limit) & (pv / np.sqrt(2) > 2 * c.noise))]
    if bad_views:
        c.findings.append(Finding(
            "outlier_views", "doubtful",
            f"view(s) {_list(bad_views)} fit far worse than the others (RMS "
            f"{', '.join(f'{pv[v]:.2f}' for v in bad_views[:6])} px against a median of {np.median(pv):.3f} px)",
            f"drop view(s) {_list(bad_views)} (a wrong or blurred detection) and calibrate again", bad_views))


def _seams(obj, res, noise) -> list[tuple[float, int, int, float, int]]:
    """Per view, the strongest step between two neighbouring grid lines: ``(z, axis, line, size px, corners)``.

    A part of a view shifted against the rest (the rows below ``line`` moved, a detector that jumped, a frame
    torn by a rolling shutter) is a step in the residuals between lines ``line`` and ``line + 1``; the pose and
    the lens absorb smooth patterns, not a step. Across each boundary, per line through it, the third difference
    ``e[l-1] - 3 e[l] + 3 e[l+1] - e[l+2]`` of the residuals is twice the step and nearly 0 for anything smooth;
    its mean over the ``m`` lines through the boundary has the standard deviation ``noise sqrt(20 / m)`` per
    coordinate under the noise model, so ``z = |mean| / (noise sqrt(20 / m))``.
    """
    out = []
    for o, e in zip(obj, res):
        g = grid_indices(o)
        P = np.full((g[:, 1].max() + 1, g[:, 0].max() + 1, 2), np.nan)
        P[g[:, 1], g[:, 0]] = e
        best = (0.0, 0, 0, 0.0, 0)
        for axis, Q in ((1, P), (0, P.transpose(1, 0, 2))):  # rows (a step between rows), then columns
            for line in range(1, Q.shape[0] - 2):
                T = Q[line - 1] - 3 * Q[line] + 3 * Q[line + 1] - Q[line + 2]
                T = T[np.all(np.isfinite(T), axis=1)]
                if len(T) < 3:
                    continue
                m = T.mean(axis=0)
                z = float(np.linalg.norm(m) / (noise * np.sqrt(20.0 / len(T))))
                if z > best[0]:
                    best = (z, axis, line, float(np.linalg.norm(m) / 2.0), len(T))
        out.append(best)
    return out


def rule_shifted_parts(c: Case) -> None:
    """A part of a view shifted against the rest of it (a step between two grid lines), named with its view."""
    if c.lines:  # a bent column or row is a step in many views: named by the line rule
        return
    for v, (z, axis, line, size, _) in enumerate(_seams(c.obj, c.res, c.noise)):
        if z <= SEAM_Z or size <= SEAM_NOISE_FACTOR * c.noise:
            continue
        name = ("row", "column")[axis == 0]
        try:
            without = c.evidence.refit([o for k, o in enumerate(c.obj) if k != v],
                                       [p for k, p in enumerate(c.img) if k != v])
            severity, cost = _robot_cost(robot_view_shift(c.result, without), c.result.image_size)
        except (DtscalError, cv2.error, np.linalg.LinAlgError):  # too few views left to tell
            severity, cost = "doubtful", ""
        message = (f"in view {v} the {name}s after {name} {line} are shifted by {size:.2f} px against the {name}s up "
                   f"to it ({z:.0f} standard errors; corner noise {c.noise:.3f} px): a part of the view moved (a "
                   "detector that jumped, a frame torn by motion), not noise")
        c.findings.append(Finding(
            "shifted_part", severity, f"{message}. {cost}" if cost else message,
            f"drop view {v} or re-detect it; look at {name}s {line} and {line + 1} on that image", [v]))


def rule_line_offsets(c: Case) -> None:
    """A column or row of corners offset the same way in many views; it then explains the residual, so the
    fit rule's unexplained residual becomes a note."""
    c.lines = _offset_findings(c.evidence.refit, c.result, c.obj, c.img, c.res, c.noise, c.evidence.dist_indices)
    c.findings += c.lines
    if c.lines:
        for f in [f for f in c.findings if f.code == "unexplained_fit"]:
            c.notes.append(Finding(f.code, "good", f.message, ""))
        c.findings = [f for f in c.findings if f.code != "unexplained_fit"]


def rule_radial(c: Case) -> None:
    """A radial residual the distortion model cannot absorb (not looked for when a bent line explains it)."""
    if c.lines or _radial_finding(c.result, c.res, c.noise) is None:
        return
    # only then the lens advice, which may fit the finer models (the costly part): what they showed is the cause
    c.findings.append(_radial_finding(c.result, c.res, c.noise, _richer_model(c.result, c.noise, c.richer)))


def rule_outlier_corners(c: Case) -> None:
    """Single corners far off where the camera puts them (not when a lens or a bent line explains them)."""
    found, c.without_corners = None, None
    if not (c.fit_blamed or c.lines):
        found, c.without_corners, _ = _outlier_corners(c.evidence.refit, c.result, c.obj, c.img, c.res)
    left_out = list(getattr(c.result, "left_out_corners", []) or [])
    if found is None and left_out:
        found = Finding(
            "outlier_corners", "doubtful",
            f"{len(left_out)} corner(s) lay far from where the camera puts them and were left out before this "
            f"calibration ({'; '.join(_corner_words(h) for h in left_out[:6])}"
            f"{f' ... ({len(left_out)} in all)' if len(left_out) > 6 else ''})",
            "nothing to do for this calibration; re-detect those views or look at them: a corner the detector put "
            "on clutter, a reflection or the board's edge", sorted({h["view"] for h in left_out}))
    if found is not None:
        c.findings.append(found)
    c.corner_finding = found


def rule_neighbour_correlation(c: Case) -> None:
    """Neighbouring corners sharing their error, beyond the noise (when nothing above explains it)."""
    rho = _neighbour_correlation(c.obj, c.res)
    if rho > NEIGHBOUR_CORRELATION and c.ratio > 1.2 and not c.lines and c.corner_finding is None:
        c.findings.append(Finding(
            # above 2x the noise the systematic part of the residual is larger than the noise itself
            # (sqrt(ratio^2 - 1) > 1.7): the parameters are biased far beyond their standard deviations
            "neighbour_correlation", "doubtful" if c.ratio <= SYSTEMATIC_RATIO_BAD else "bad",
            f"neighbouring corners share their error (correlation {rho:.2f} of adjacent residuals, 0 for noise) "
            f"and the residuals are {c.ratio:.1f} times the corner noise: a pattern the {c.result.model} model "
            "cannot absorb, which biases the parameters beyond their standard deviations",
            f"{_richer_model(c.result, c.noise, c.richer)}; check that the board is flat and its squares are the "
            "size given"))


def rule_few_views(c: Case) -> None:
    """Too few views to tell a wrong view from the rest."""
    if c.result.n_views < MIN_GOOD_VIEWS:
        c.findings.append(Finding(
            "few_views", "doubtful",
            f"only {c.result.n_views} views: too few to tell a wrong view from the rest",
            f"collect at least {MIN_GOOD_VIEWS} (better 20 or more) views at different places and tilts"))


def rule_parallel_views(c: Case) -> None:
    """Boards all nearly parallel."""
    spread = c.evidence.tilt_spread_deg
    if spread < TILT_DOUBTFUL_DEG:
        c.findings.append(Finding(
            "parallel_views", "bad" if spread < TILT_BAD_DEG else "doubtful",
            f"the boards are nearly parallel: every board normal is within {spread:.1f} degrees of their mean",
            "tilt the board left/right and up/down by 20-45 degrees in further views"))


def rule_robot_view(c: Case) -> None:
    """The projection uncertainty where the robot looks (:func:`~dtscal_lib.uncertainty.robot_view`): the one
    uncertainty that can make a calibration bad."""
    if c.umap is None:
        return
    s = robot_view_sigma(c.umap, c.result.image_size)
    w, h = c.result.image_size
    where = "the DD24's view" if h > w else "the lower half of the image (the ground ahead of a Duckiebot)"
    if not np.isfinite(s):
        c.findings.append(Finding(
            "robot_view", "bad",
            f"the distortion model cannot be inverted in {where}: fitted without corners there, it folds over "
            "and does not describe the lens where the robot looks",
            f"hold the board next in the {c.help_region} of the image, filling the lower half of the image"))
    elif s > ROBOT_VIEW_SIGMA_DOUBTFUL:
        c.findings.append(Finding(
            "robot_view", "bad" if s > ROBOT_VIEW_SIGMA_BAD else "doubtful",
            f"where the robot looks ({where}) a pixel can move by {s:.2f} px on average (1 sigma) within the "
            f"parameters' uncertainty (doubtful above {ROBOT_VIEW_SIGMA_DOUBTFUL:g} px, bad above "
            f"{ROBOT_VIEW_SIGMA_BAD:g} px)",
            "collect more views filling the lower half of the image, tilted"))


def rule_coverage(c: Case) -> None:
    """The uncertainty at the image corners, where no board reached: advice (hold the board there), never
    bad; the robot's own view is :func:`rule_robot_view`'s."""
    u = c.umap
    if u is None or any(f.code == "robot_view" and f.severity == "bad" for f in c.findings):
        return
    if np.isnan(u.corner_mean):
        c.findings.append(Finding(
            "uncertainty", "doubtful",
            "the distortion model cannot be inverted at the image corners: fitted without corners there, "
            "it folds over there (the robot's own view is not affected)",
            f"hold the board next in the {c.help_region} of the image and in the other image corners"))
    elif u.corner_mean > CORNER_SIGMA_DOUBTFUL:
        c.findings.append(Finding(
            "uncertainty", "doubtful",
            f"a pixel at the image corners, where no board was seen, can move by {u.corner_mean:.2f} px (1 sigma) "
            "within the parameters' uncertainty",
            f"hold the board next in the {c.help_region} of the image (filling it, tilted), where the uncertainty "
            "is largest"))


#: the verdict's rules, in the order they run (a later rule reads what an earlier one found)
RULES: tuple[tuple[str, Callable[[Case], None]], ...] = (
    ("converged", rule_converged),
    ("fit", rule_fit),
    ("outlier_views", rule_outlier_views),
    ("line_offsets", rule_line_offsets),
    ("radial", rule_radial),
    ("outlier_corners", rule_outlier_corners),
    ("shifted_parts", rule_shifted_parts),
    ("neighbour_correlation", rule_neighbour_correlation),
    ("few_views", rule_few_views),
    ("parallel_views", rule_parallel_views),
    ("robot_view", rule_robot_view),
    ("coverage", rule_coverage),
)


def run_rules(case: Case) -> Case:
    """Every rule of :data:`RULES`, in order, on ``case``."""
    for _, rule in RULES:
        rule(case)
    return case
