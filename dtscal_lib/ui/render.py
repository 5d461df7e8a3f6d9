"""Pure drawing and formatting helpers of the live tools: images to JPEG, bars, tables, charts.

Nothing here holds state; every function takes arrays or results and returns bytes, arrays
or HTML text, so the frame loop can be benchmarked and tested without a browser.
"""

from __future__ import annotations

import html
import math

import cv2
import numpy as np

from ..figure import BAD_COLOR, GOOD_COLOR, GREY as _GREYS, PALETTE, WARN_COLOR, bgr

#: JPEG quality of the live views (the widget sends each frame as one JPEG)
JPEG_QUALITY = 80
#: good (a full bar, a good verdict), still filling, bad (a dropped sample, an error): the kit's palette
#: (dtscal_lib.figure), told apart under deuteranopia and protanopia (tests/test_figure_palette.py)
GREEN, GREY, RED = GOOD_COLOR, _GREYS["mid"], BAD_COLOR


def encode_jpeg(image: np.ndarray, quality: int = JPEG_QUALITY) -> bytes:
    """BGR or gray uint8 image -> JPEG bytes for an ``ipywidgets.Image``."""
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:  # pragma: no cover - OpenCV only fails on empty input, checked by callers
        raise ValueError("could not encode the image as JPEG")
    return buf.tobytes()


def placeholder_jpeg(text: str, size: tuple[int, int] = (640, 480)) -> bytes:
    """A grey JPEG that says ``text``: what a live view shows before its first frame (a browser shows a
    broken-image icon for an empty image), e.g. the preview before CALIBRATE or a robot that never answered.
    Long text is wrapped at word boundaries."""
    w, h = size
    img = np.full((h, w, 3), 236, np.uint8)
    cv2.rectangle(img, (0, 0), (w - 1, h - 1), (200, 200, 200), 2)
    scale, thick = max(0.4, w / 1000.0), 1
    lines, line = [], ""
    for word in text.split():
        trial = f"{line} {word}".strip()
        if cv2.getTextSize(trial, cv2.FONT_HERSHEY_SIMPLEX, scale, thick)[0][0] > w - 40 and line:
            lines.append(line)
            line = word
        else:
            line = trial
    lines.append(line)
    step = int(cv2.getTextSize("Ag", cv2.FONT_HERSHEY_SIMPLEX, scale, thick)[0][1] * 2.0)
    y = (h - step * (len(lines) - 1)) // 2
    for ln in lines:
        tw = cv2.getTextSize(ln, cv2.FONT_HERSHEY_SIMPLEX, scale, thick)[0][0]
        cv2.putText(img, ln, ((w - tw) // 2, y), cv2.FONT_HERSHEY_SIMPLEX, scale, (90, 90, 90), thick, cv2.LINE_AA)
        y += step
    return encode_jpeg(img)


def stamp_classes(index: int, arrival: float, shown: int | None = None, tool: str = "") -> tuple[str, ...]:
    """CSS classes that tag a live image with its frame and its arrival time (ms since the epoch).

    They travel in the same widget update as the image, so a page (the browser test) can
    measure the time from a frame's arrival in the kernel to its display. ``shown`` is the
    display pacer's token, which the page echoes back once the image has loaded
    (:class:`~dtscal_lib.ui.frameloop.DisplayPacer`); ``tool`` names the tool
    (``dtscal-live-<tool>``).
    """
    classes = ["dtscal-live", f"dtscal-frame-{int(index)}", f"dtscal-at-{int(round(arrival * 1000))}"]
    if shown is not None:
        classes.append(f"dtscal-shown-{int(shown)}")
    if tool:
        classes.append(f"dtscal-live-{tool}")
    return tuple(classes)


def thumbnail(image: np.ndarray, corners: np.ndarray | None, width: int = 96) -> bytes:
    """A small JPEG of a sample: the frame scaled to ``width`` with the board outline drawn."""
    h, w = image.shape[:2]
    s = width / float(w)
    small = cv2.resize(image, (width, max(1, int(round(h * s)))), interpolation=cv2.INTER_AREA)
    if small.ndim == 2:
        small = cv2.cvtColor(small, cv2.COLOR_GRAY2BGR)
    if corners is not None:
        pts = np.round(np.asarray(corners, dtype=np.float64) * s).astype(np.int32).reshape(-1, 1, 2)
        cv2.polylines(small, [cv2.convexHull(pts)], True, bgr(GOOD_COLOR), 1, cv2.LINE_AA)
    return encode_jpeg(small, 75)


def bars_html(bars) -> str:
    """The four coverage bars (``coverage.Bar``) as HTML: grey while filling, green when full."""
    rows = []
    for b in bars:
        pct = int(round(100 * max(0.0, min(1.0, b.progress))))
        colour = GREEN if b.full else GREY
        rows.append(
            f'<div class="dtscal-bar" data-name="{b.name}" data-full="{int(b.full)}" style="display:flex;'
            f'align-items:center;gap:6px;margin:2px 0"><span style="width:36px">{b.name}</span>'
            f'<span style="display:inline-block;width:180px;height:12px;background:{_GREYS["pale"]};border-radius:3px">'
            f'<span style="display:block;width:{pct}%;height:12px;background:{colour};border-radius:3px"></span>'
            f"</span><span>{pct}%</span></div>"
        )
    return "".join(rows)


def _fmt(v: float, digits: int = 3) -> str:
    return f"{v:.{digits}f}"


def matrix_html(M: np.ndarray, digits: int = 3) -> str:
    rows = "".join("<tr>" + "".join(f'<td style="text-align:right;padding:0 6px">{_fmt(v, digits)}</td>' for v in r)
                   + "</tr>" for r in np.atleast_2d(M))
    return f'<table style="font-family:monospace">{rows}</table>'


def error_chart_svg(per_view_rms, dropped_positions=(), width: int = 360, height: int = 90) -> str:
    """Per-sample RMS reprojection error as an inline SVG bar chart (red: dropped as outliers)."""
    v = np.asarray(per_view_rms, dtype=np.float64)
    if v.size == 0:
        return ""
    top = float(np.max(v)) or 1.0
    n = v.size
    bw = max(1.0, (width - 30) / n)
    bars = []
    for i, e in enumerate(v):
        hgt = (height - 16) * float(e) / top
        colour = RED if i in set(dropped_positions) else PALETTE["blue"]
        bars.append(f'<rect x="{28 + i * bw:.1f}" y="{height - 12 - hgt:.1f}" width="{max(0.8, bw - 1):.1f}" '
                    f'height="{hgt:.1f}" fill="{colour}"><title>sample {i + 1}: {e:.3f} px</title></rect>')
    return (f'<svg width="{width}" height="{height}" style="background:#FAFAFA">'
            f'<text x="0" y="10" font-size="9">{top:.2f} px</text>'
            f'<text x="0" y="{height - 2}" font-size="9">0</text>'
            f'<text x="{width - 90}" y="{height - 2}" font-size="9">sample 1..{n}</text>' + "".join(bars) + "</svg>")


_COEFFS = {"rational_polynomial": "[k1, k2, p1, p2, k3, k4, k5, k6]", "equidistant": "[k1, k2, k3, k4]"}


def calibration_html(result, dropped: list[int], n_samples: int, verdict: str | None = None,
                     against: str | None = None) -> str:
    """The results panel of the live calibrator for a ``CalibrationResult``."""
    K, d = result.K, np.asarray(result.dist).ravel()
    std = "".join(f"<tr><td>{html.escape(k)}</td><td style='text-align:right'>{v:.4g}</td></tr>"
                  for k, v in result.std.items())
    kept = [i for i in range(n_samples) if i not in set(dropped)]
    note = (f"{len(dropped)} sample(s) dropped as outlier views: "
            + ", ".join(str(i + 1) for i in dropped)) if dropped else "no outlier view"
    parts = [
        f'<div class="dtscal-result" data-rms="{result.rms:.6f}">',
        f"<b>Calibration</b> ({result.model}, {len(kept)} of {n_samples} samples; {note})<br>",
        f"<b>RMS</b> reprojection error: {result.rms:.3f} px<br>",
        "<b>K</b>" + matrix_html(K, 3),
        f"<b>distortion</b> {_COEFFS.get(result.model, '[k1, k2, p1, p2, k3]')}: "
        + ", ".join(f"{x:.5f}" for x in d) + "<br>",
        "<b>standard deviations</b><table style='font-family:monospace'>" + std + "</table>",
        "<b>per-sample RMS (px)</b><br>" + error_chart_svg(result.per_view_rms),
    ]
    if verdict:
        parts.append("<br><b>verdict</b> " + verdict)
    if against:
        parts.append(f'<br><b>against the robot\'s file</b> <span class="dtscal-against">{html.escape(against)}</span>')
    parts.append("</div>")
    return "".join(parts)


def message_html(text: str, kind: str = "info") -> str:
    """One status line; ``kind`` is ``info``, ``ok`` or ``error`` (colour only)."""
    colour = {"ok": GREEN, "error": RED}.get(kind, _GREYS["dark"])
    return f'<div class="dtscal-msg dtscal-{kind}" style="color:{colour}">{html.escape(text)}</div>'


def source_status_html(spec: str, status, bad: dict, kept: str) -> str:
    """The status line of a live tool for a :class:`~dtscal_lib.sources.live.LiveStatus`.

    ``kept`` says what survives a lost source (``"Every sample is kept"``); ``bad`` counts the
    skipped frames by reason.
    """
    waiting = status.state == "connecting" and status.message and not status.message.startswith("connecting to ")
    never = status.frames == 0  # a source that never sent a frame was never connected: it cannot be "lost"
    said = (status.message or "").rstrip(". ")
    # the button's advice once: a message that already says to press Reconnect (the ROS diagnosis) keeps its own
    own = "press reconnect" in said.lower()
    text = {"connecting": f"waiting for {spec}: {status.message}" if waiting else f"connecting to {spec} ...",
            "running": f"live: {spec}",
            "ended": f"source ended: {said}. {kept}" + ("." if own else "; RECONNECT to go on."),
            "error": (f"could not connect to {spec}: {said}." + ("" if own else " RECONNECT to try again.") if never
                      else f"source lost: {said}. {kept}" + ("." if own else "; RECONNECT when it is back."))}.get(
        status.state, status.message)
    if bad:
        text += " (skipped frames: " + ", ".join(f"{k} {v}" for k, v in sorted(bad.items())) + ")"
    return message_html(text, "error" if status.state in ("ended", "error") else "info")


def top_view(ground_true: np.ndarray, ground_fit: np.ndarray | None, *, px_per_m: float = 1600.0,
             x_range=(0.16, 0.36), y_range=(-0.13, 0.13), magnify: float = 20.0) -> np.ndarray:
    """A top view of the board on the ground: true corner positions (circles) and where the
    fitted homography puts the detected corners (crosses), errors drawn ``magnify`` times longer.

    x (forward) points up, y (left) points left, as in :func:`dtscal_lib.ground.birdseye_view`.
    Returns a BGR uint8 image.
    """
    (x0, x1), (y0, y1) = x_range, y_range
    w, h = int(round((y1 - y0) * px_per_m)), int(round((x1 - x0) * px_per_m))
    img = np.full((h, w, 3), 255, np.uint8)

    def to_px(g):
        g = np.asarray(g, dtype=np.float64).reshape(-1, 2)
        return np.column_stack([(y1 - g[:, 1]) * px_per_m, (x1 - g[:, 0]) * px_per_m])

    step = 0.01
    for x in np.arange(math.ceil(x0 / step) * step, x1, step):
        r = int(round((x1 - x) * px_per_m))
        cv2.line(img, (0, r), (w - 1, r), (235, 235, 235), 1)
    for y in np.arange(math.ceil(y0 / step) * step, y1, step):
        c = int(round((y1 - y) * px_per_m))
        cv2.line(img, (c, 0), (c, h - 1), (235, 235, 235), 1)
    true_px = to_px(ground_true)
    for p in true_px:
        cv2.circle(img, (int(round(p[0])), int(round(p[1]))), 5, (120, 120, 120), 1, cv2.LINE_AA)
    if ground_fit is not None:
        g_true = np.asarray(ground_true, dtype=np.float64).reshape(-1, 2)
        g_fit = np.asarray(ground_fit, dtype=np.float64).reshape(-1, 2)
        shown = to_px(g_true + magnify * (g_fit - g_true))
        for a, b in zip(true_px, shown):
            pa, pb = (int(round(a[0])), int(round(a[1]))), (int(round(b[0])), int(round(b[1])))
            cv2.line(img, pa, pb, bgr(BAD_COLOR), 1, cv2.LINE_AA)
            cv2.drawMarker(img, pb, bgr(BAD_COLOR), cv2.MARKER_CROSS, 7, 1)
    cv2.putText(img, f"errors x{magnify:g}; grid 1 cm", (6, h - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                (60, 60, 60), 1, cv2.LINE_AA)
    return img


def verdict_html(quality) -> str | None:
    """The verdict part of the live calibrator's results panel (a Quality, or a message when there is none)."""
    if quality is None:
        return None
    if isinstance(quality, str):
        return message_html(quality)
    findings = "".join(f"<li>{html.escape(str(f.message))} <i>{html.escape(str(f.advice))}</i></li>"
                       for f in getattr(quality, "findings", []))
    colour = {"good": GREEN, "bad": RED}.get(str(quality.verdict), WARN_COLOR)
    return (f'<span class="dtscal-verdict" style="color:{colour}"><b>{html.escape(str(quality.verdict))}</b></span>'
            + (f"<ul>{findings}</ul>" if findings else ""))


def rectification_maps_fast(cam):
    """``cam.rectification_maps()`` for the live views, computed by ``cv2.initUndistortRectifyMap``.

    The kit's own :func:`~dtscal_lib.camera.rectification_maps` (numpy) takes ~0.1 s of CPU at
    640x480 and holds the interpreter meanwhile; OpenCV's gives the same maps (to float32
    resolution, checked in the tests) in a few milliseconds without holding it. OpenCV ignores
    the skew of K, so a camera with skew keeps the kit's maps.
    """
    if cam.K[0, 1] != 0.0:
        return cam.rectification_maps()
    return cam.opencv_maps()


def outline_thumb(corners: np.ndarray, size, width: int = 96) -> bytes:
    """Thumbnail of a loaded sample (the frame is not saved): the board outline on grey."""
    blank = np.full((size[1], size[0], 3), 200, np.uint8)
    return thumbnail(blank, corners, width)
