"""Figures that show how good a calibration is, and the ``--report`` page that gathers them.

Every ``fig_*`` function takes a :class:`~dtscal_lib.calibration.CalibrationResult` (and, to avoid
recomputing it, its :class:`~dtscal_lib.quality.Quality`) and returns a matplotlib ``Figure``
built without pyplot: no global figure state, nothing shown by itself, safe in a headless CLI, a
notebook (the figure displays as the cell's value) and the live calibrator alike.

- :func:`fig_view_rms` -- RMS per view against the corner noise; views that fit far worse in red
- :func:`fig_worst_residuals` -- residual vectors (magnified) of the worst views
- :func:`fig_residual_histogram` -- residual coordinates against the noise model
- :func:`fig_uncertainty_map` -- 1-sigma projection uncertainty over the image
- :func:`fig_coverage` -- where in the image the corners came from
- :func:`write_report` -- all of them as PNGs plus one ``index.html`` with the verdict
- :func:`show` -- display figures in a notebook cell as PNG images

Example
-------
>>> import numpy as np
>>> from dtscal_lib import camera, duckietown as dt
>>> from dtscal_lib.boards import DUCKIETOWN_BOARD
>>> from dtscal_lib.calibration import calibrate
>>> obj = DUCKIETOWN_BOARD.object_points()
>>> poses = [([0.3, 0.1, 0.0], [-0.1, -0.06, 0.35]), ([-0.2, 0.3, 0.1], [-0.1, -0.05, 0.4]),
...          ([0.1, -0.35, -0.1], [-0.08, -0.07, 0.3]), ([-0.3, -0.2, 0.2], [-0.1, -0.04, 0.45])]
>>> rng = np.random.default_rng(0)
>>> img = [camera.project_points(obj, r, t, dt.default_K(), dt.default_dist()) + rng.normal(0, 0.05, (35, 2))
...        for r, t in poses]
>>> fig = fig_view_rms(calibrate([obj] * 4, img, dt.IMAGE_SIZE))
>>> len(fig.axes)
1
"""

from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from .figure import (BAD_COLOR, GOOD_COLOR, GREY, PALETTE, WARN_COLOR,  # the kit's one figure convention and palette
                     CourseFigure, outlined)

from . import safe_write
from .errors import DtscalError
from .quality import REGION_NAMES, Quality

__all__ = ["fig_view_rms", "fig_worst_residuals", "fig_residual_histogram", "fig_uncertainty_map", "fig_coverage",
           "write_report", "show", "quality_for_run", "FIGURES"]

_VERDICT_COLOUR = {"good": GOOD_COLOR, "doubtful": WARN_COLOR, "bad": BAD_COLOR}


def _q(result, quality: Quality | None) -> Quality:
    return result.quality() if quality is None else quality


def _image_axes(ax, size) -> None:
    w, h = size
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_aspect("equal")
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")


def fig_view_rms(result, quality: Quality | None = None) -> Figure:
    """Bar chart of each view's RMS; the noise model's expectation and the outlier limit as lines."""
    from .quality import VIEW_OUTLIER_FACTOR

    q = _q(result, quality)
    pv = np.asarray(result.per_view_rms)
    flagged = set(v for f in q.findings if f.code in ("outlier_views", "column_offset", "row_offset") for v in f.views)
    fig = CourseFigure(figsize=(8, 3.2), layout="constrained")
    fig.alt = ("Each view's RMS reprojection error against what the corner noise predicts; views far above "
                "the line fit worse than noise explains.")
    ax = fig.add_subplot()
    colours = [BAD_COLOR if v in flagged else PALETTE["blue"] for v in range(len(pv))]
    ax.bar(np.arange(len(pv)), pv, color=colours, width=0.8)
    ax.axhline(np.sqrt(2) * q.noise_sigma, color="k", ls="--", lw=1,
               label=f"expected from corner noise ({np.sqrt(2) * q.noise_sigma:.3f} px)")
    ax.axhline(VIEW_OUTLIER_FACTOR * np.median(pv), color=BAD_COLOR, ls=":", lw=1,
               label=f"{VIEW_OUTLIER_FACTOR:g} x median view")
    ax.set_xlabel("view")
    ax.set_ylabel("RMS reprojection error (px)")
    ax.set_title(f"RMS per view (red: named in the verdict); overall {result.rms:.3f} px")
    ax.legend(loc="upper right", fontsize=8)
    return fig


def fig_worst_residuals(result, quality: Quality | None = None, n: int = 4) -> Figure:
    """Residual vectors (observed -> projected, magnified) of the ``n`` views with the largest RMS."""
    q = _q(result, quality)
    worst = list(np.argsort(-np.asarray(result.per_view_rms))[:n])
    fig = CourseFigure(figsize=(4.2 * len(worst), 3.6), layout="constrained")
    fig.alt = "The residual vectors of the views that fit worst, magnified, one panel per view."
    big = max(float(np.abs(np.concatenate([q.residuals[v] for v in worst])).max()), 1e-12)
    scale = 25.0 / big  # the longest arrow is 25 px long on the image
    for k, v in enumerate(worst):
        ax = fig.add_subplot(1, len(worst), k + 1)
        p, e = np.asarray(result.image_points[v]).reshape(-1, 2), q.residuals[v]
        ax.plot(p[:, 0], p[:, 1], ".", color=GREY["mid"], ms=3)
        ax.quiver(p[:, 0], p[:, 1], e[:, 0] * scale, e[:, 1] * scale, angles="xy", scale_units="xy", scale=1,
                  color=BAD_COLOR, width=0.006)
        _image_axes(ax, result.image_size)
        lo, hi = p.min(axis=0), p.max(axis=0)
        pad = 0.2 * (hi - lo).max() + 30.0  # the board and its arrows, not the whole image
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(hi[1] + pad, lo[1] - pad)
        ax.set_title(f"view {v}: RMS {result.per_view_rms[v]:.3f} px", fontsize=9)
    fig.suptitle(f"residuals of the worst views, magnified x{scale:.3g}", fontsize=10)
    return fig


def fig_residual_histogram(result, quality: Quality | None = None) -> Figure:
    """Histogram of all residual coordinates against the noise model's Gaussian."""
    q = _q(result, quality)
    e = np.concatenate(q.residuals).ravel()
    fig = CourseFigure(figsize=(6, 3.4), layout="constrained")
    fig.alt = "Histogram of the corners' reprojection residuals, in pixels."
    ax = fig.add_subplot()
    lim = max(4 * q.noise_sigma, float(np.quantile(np.abs(e), 0.995)))
    bins = np.linspace(-lim, lim, 61)
    ax.hist(np.clip(e, -lim, lim), bins=bins, density=True, color=PALETTE["blue"], alpha=0.7,
            label="residuals (u and v)")
    x = np.linspace(-lim, lim, 400)
    for s, style, colour, what in ((q.noise_sigma, "--", "k", "corner noise"),
                                   (q.fit_sigma, "-", BAD_COLOR, "fit")):
        ax.plot(x, np.exp(-0.5 * (x / s) ** 2) / (s * np.sqrt(2 * np.pi)), style, color=colour, lw=1,
                label=f"Gaussian, {what} sigma {s:.3f} px")
    ax.set_xlabel("residual (px)")
    ax.set_ylabel("density")
    ax.set_title("residuals against the noise model")
    ax.legend(fontsize=8)
    return fig


def fig_uncertainty_map(result, quality: Quality | None = None) -> Figure:
    """1-sigma (worst direction) projection uncertainty over the image, observed corners on top."""
    q = _q(result, quality)
    u = q.uncertainty
    fig = CourseFigure(figsize=(6.4, 5), layout="constrained")
    fig.alt = ("Map over the image of the 1-sigma projection uncertainty in pixels (colour, log scale), the "
                "observed corners on top and the value at each image corner labelled.")
    ax = fig.add_subplot()
    if u is None:
        ax.text(0.5, 0.5, "uncertainty not computed", ha="center", va="center", transform=ax.transAxes)
        return fig
    finite = u.sigma[np.isfinite(u.sigma)]
    lo, hi = (finite.min(), finite.max()) if finite.size else (1e-6, 2e-6)
    levels = np.geomspace(max(lo, 1e-6), max(hi, 2 * max(lo, 1e-6)), 12)
    cs = ax.contourf(u.u, u.v, u.sigma, levels=levels, cmap="viridis", norm=_log_norm(levels))
    fig.colorbar(cs, ax=ax, label="1-sigma projection uncertainty (px)", format="%.3g")
    pts = np.concatenate([np.asarray(p).reshape(-1, 2) for p in result.image_points])
    ax.plot(pts[:, 0], pts[:, 1], ",", color="w", alpha=0.5)
    for (x, y), s in zip(u.corners, u.corner_sigma):
        ax.text(x + (10 if x < 1 else -10), y + (22 if y < 1 else -12), "?" if np.isnan(s) else f"{s:.2f} px",
                ha="left" if x < 1 else "right", color="w", fontsize=9, weight="bold",
                path_effects=outlined())  # white on any colour of the map: a dark outline keeps it legible
    _image_axes(ax, result.image_size)
    where = "infinity" if not np.isfinite(u.distance) else f"{u.distance:.3g} m"
    corners = ("lens model not invertible there (grey)" if np.isnan(u.corner_mean)
               else f"{u.corner_mean:.2f} px (1 sigma)")
    ax.set_facecolor("0.8")
    ax.set_title(f"projection uncertainty, points at distance {where}\nimage corners: {corners}; "
                 f"more data would help most: {u.worst_region()}", fontsize=9)
    return fig


def _log_norm(levels):
    from matplotlib.colors import LogNorm

    return LogNorm(vmin=levels[0], vmax=levels[-1])


def fig_coverage(result, quality: Quality | None = None) -> Figure:
    """Every observed corner on the image, with the count per ninth of the image."""
    q = _q(result, quality)
    w, h = result.image_size
    fig = CourseFigure(figsize=(6.4, 5), layout="constrained")
    fig.alt = "Every observed corner on the image, with the count of corners in each ninth of the image."
    ax = fig.add_subplot()
    for v, p in enumerate(result.image_points):
        p = np.asarray(p).reshape(-1, 2)
        ax.plot(p[:, 0], p[:, 1], ".", ms=2, alpha=0.6)
    for k in (1, 2):
        ax.axvline(k * w / 3, color=GREY["mid"], lw=0.8)
        ax.axhline(k * h / 3, color=GREY["mid"], lw=0.8)
    for r in range(3):
        for c in range(3):
            n = int(q.corner_counts[r, c])
            ax.text((c + 0.5) * w / 3, (r + 0.5) * h / 3, str(n), ha="center", va="center", fontsize=12,
                    color=BAD_COLOR if REGION_NAMES[r][c] == q.help_region else "k", alpha=0.8)
    _image_axes(ax, result.image_size)
    ax.set_title(f"where the corners came from ({result.n_points} corners, {result.n_views} views); "
                 f"red: add views here", fontsize=9)
    return fig


def show(*figs: Figure, dpi: int = 100) -> None:
    """Display figures in a notebook as PNG images, whatever matplotlib backend is active.

    A pyplot-free ``Figure`` shows as the cell's value only once the inline backend is configured;
    this works in any cell (and in the live calibrator's output widgets).
    """
    import io

    from IPython.display import Image, display

    for fig in figs:
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=dpi)
        display(Image(data=buf.getvalue(), format="png"))


#: file name -> (function, caption) of the report's figures, in page order
FIGURES = {
    "view_rms.png": (fig_view_rms, "Reprojection RMS of every view against what the corner noise predicts."),
    "worst_residuals.png": (fig_worst_residuals, "Residual vectors of the worst views (magnified): a pattern "
                            "(one column, one direction, a swirl) is a cause, random arrows are noise."),
    "residual_histogram.png": (fig_residual_histogram, "All residual coordinates against the noise model."),
    "uncertainty_map.png": (fig_uncertainty_map, "How far a pixel's projection can move (1 sigma) within the "
                            "parameters' uncertainty."),
    "coverage.png": (fig_coverage, "Where in the image the corners came from."),
}


def write_report(result, directory, quality: Quality | None = None, *, title: str = "Calibration report",
                 extra: dict | None = None) -> Path:
    """Write the figures as PNGs and an ``index.html`` with the verdict into ``directory``; returns the page.

    ``extra`` : optional ``{label: value}`` rows for the summary table (robot, source, ...).
    """
    out = Path(directory)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DtscalError(f"cannot create the report folder {out} ({exc.strerror or exc}); give a folder "
                          "that can be written, e.g. --report report") from None
    q = _q(result, quality)
    for name, (fn, _) in FIGURES.items():
        fig = fn(result, q)
        with safe_write.output(out / name, what="report figure", suffix=".png") as tmp:
            fig.savefig(tmp, dpi=100, format="png")
    rows = dict(extra or {})
    K = result.K
    rows.update({
        "views / corners": f"{result.n_views} / {result.n_points}",
        "model": result.model + (" + skew" if result.skew else ""),
        "fx, fy": f"{K[0, 0]:.3f} &plusmn; {result.std.get('fx', float('nan')):.3f}, "
                  f"{K[1, 1]:.3f} &plusmn; {result.std.get('fy', float('nan')):.3f} px",
        "cx, cy": f"{K[0, 2]:.3f} &plusmn; {result.std.get('cx', float('nan')):.3f}, "
                  f"{K[1, 2]:.3f} &plusmn; {result.std.get('cy', float('nan')):.3f} px",
        "dist": ", ".join(f"{d:.5f}" for d in result.dist),
        "RMS / residual sigma": f"{result.rms:.3f} / {q.fit_sigma:.3f} px",
        "noise model": html.escape(q.noise_model),
        "projection uncertainty at the image corners":
            "-" if q.uncertainty is None else "the lens model cannot be inverted there"
            if np.isnan(q.uncertainty.corner_mean) else f"{q.uncertainty.corner_mean:.3f} px (1 sigma)",
        "more data would help most": html.escape(q.help_region),
        "+- (1 sigma) computed as": getattr(result, "std_method", "") or "-",
        "what it means for a Duckiebot": q.meaning(),  # verdict, why, ground projection at 30 and 60 cm
    })
    colour = _VERDICT_COLOUR[q.verdict]
    findings = "".join(
        f"<li><b>{html.escape(f.severity)}</b> ({html.escape(f.code)}): {html.escape(f.message)}."
        f"<br><i>What to do:</i> {html.escape(f.advice)}</li>" for f in q.findings) or "<li>none</li>"
    table = "".join(f"<tr><th>{html.escape(str(k))}</th><td>{v if k in _RAW else html.escape(str(v))}</td></tr>"
                    for k, v in rows.items())
    figs = "".join(f'<figure><img src="{name}" alt="{html.escape(cap)}"><figcaption>{html.escape(cap)}'
                   "</figcaption></figure>" for name, (_, cap) in FIGURES.items())
    data = json.dumps(q.to_dict()).replace("</", "<\\/")  # cannot end the script element early
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em}}
.verdict{{font-size:1.6em;color:#000;background:{colour};padding:.3em .8em;display:inline-block;border-radius:4px}}
th{{text-align:left;padding-right:1em}} img{{max-width:100%}} figure{{margin:1.5em 0}}</style></head>
<body><h1>{html.escape(title)}</h1>
<p class="verdict" id="verdict">{html.escape(q.verdict)}</p>
<h2>Findings</h2><ul id="findings">{findings}</ul>
<h2>Summary</h2><table>{table}</table>
<h2>Figures</h2>{figs}
<script type="application/json" id="quality">{data}</script>
</body></html>
"""
    index = out / "index.html"
    safe_write.write_text(index, page, what="report page")
    return index


_RAW = {"fx, fy", "cx, cy", "noise model", "more data would help most"}


def quality_for_run(run, report_dir=None, *, stream=None) -> Quality | None:
    """The CLI's step after ``calibrate-intrinsics``: the session's verdict, as warnings and the report page.

    The verdict is the session's (:meth:`dtscal_lib.session.IntrinsicSession.quality`), computed before
    anything was written; it is not computed again here. Every finding of a verdict that is not good goes
    to ``stream`` (default stderr) as one ``dtscal: warning: ...`` line saying what to do; with
    ``report_dir`` the figures and ``index.html`` are written there and the page's path is returned as
    ``quality.report_path``. None when the session could give no verdict (kept with ``--keep-anyway``).
    """
    import sys

    stream = sys.stderr if stream is None else stream
    q = run.quality
    if not isinstance(q, Quality):
        print(f"dtscal: warning: {q}", file=stream)
        return None
    for w in q.warnings():
        print(f"dtscal: warning: {w}", file=stream)
    if report_dir is not None:
        q.report_path = write_report(run.result, report_dir, q, title=f"Intrinsic calibration of {run.robot}",
                                     extra={"robot": run.robot, "source": run.source,
                                            "samples used": run.samples})
    return q
