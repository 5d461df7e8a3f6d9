"""Figures everyone can read: a colour-blind-safe palette, legible sizes, and an alt text on every stored figure.

The palette is checked by simulating colour-vision deficiency with the matrices of Machado, Oliveira and
Fernandes, "A physiologically-based model for simulation of color vision deficiency", IEEE TVCG 15(6), 2009
(severity 1.0, applied to linear RGB), and measuring the CIE76 colour difference (Delta E*ab) of every pair in
CIELAB. matplotlib's own red and green ("tab:red", "tab:green") are 7.3 apart under deuteranopia: a pair a
deuteranope can barely tell apart; every pair of the kit's palette must stay at least 15 apart.
"""

from __future__ import annotations

import ast
import base64
import html
import io
import itertools
import re
from pathlib import Path
from types import SimpleNamespace

import nbformat
import numpy as np
import pytest

from dtscal_lib import figure
from nbtools import SOLUTIONS

#: Machado et al. 2009, Table 1, severity 1.0 (linear RGB -> simulated linear RGB)
MACHADO = {
    "deuteranopia": np.array([[0.367322, 0.860646, -0.227968], [0.280085, 0.672501, 0.047413],
                              [-0.011820, 0.042940, 0.968881]]),
    "protanopia": np.array([[0.152286, 1.052583, -0.204868], [0.114503, 0.786281, 0.099216],
                            [-0.003882, -0.048116, 1.051998]]),
}
MIN_DELTA_E = 15.0


def _linear(hex_colour: str) -> np.ndarray:
    c = np.array([int(hex_colour[i:i + 2], 16) / 255 for i in (1, 3, 5)])
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)  # sRGB decoding (IEC 61966-2-1)


def _lab(rgb_linear: np.ndarray) -> np.ndarray:
    xyz = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]]) @ np.clip(
        rgb_linear, 0, 1)
    t = xyz / np.array([0.95047, 1.0, 1.08883])  # D65 white
    f = np.where(t > (6 / 29) ** 3, np.cbrt(t), t / (3 * (6 / 29) ** 2) + 4 / 29)
    return np.array([116 * f[1] - 16, 500 * (f[0] - f[1]), 200 * (f[1] - f[2])])


def _delta_e(a: str, b: str, m: np.ndarray) -> float:
    return float(np.linalg.norm(_lab(m @ _linear(a)) - _lab(m @ _linear(b))))


def test_the_check_itself_flags_matplotlibs_red_green_pair():
    assert _delta_e("#d62728", "#2ca02c", MACHADO["deuteranopia"]) < MIN_DELTA_E
    assert _delta_e("#d62728", "#2ca02c", np.eye(3)) > 100  # obvious to a trichromat


@pytest.mark.parametrize("deficiency", sorted(MACHADO))
def test_every_palette_pair_stays_distinguishable(deficiency):
    m = MACHADO[deficiency]
    colours = dict(figure.PALETTE)
    colours.update(board=figure.BOARD_COLOR, truth=figure.TRUTH_COLOR, other=figure.OTHER_COLOR,
                   arrow=figure.ARROW_COLOR)
    bad = [(a, b, round(_delta_e(ca, cb, m), 1)) for (a, ca), (b, cb) in itertools.combinations(colours.items(), 2)
           if ca.lower() != cb.lower() and _delta_e(ca, cb, m) < MIN_DELTA_E]
    assert not bad, f"pairs too close under {deficiency} (Delta E < {MIN_DELTA_E}): {bad}"


def test_alt_text_is_a_sentence_with_the_panels():
    fig = figure.new_figure(3, 2)
    fig.alt = "The board seen by the camera."
    ax = fig.add_subplot()
    ax.set_title("straight on")
    ax.set_xlabel("u (px)")
    assert repr(fig) == "The board seen by the camera. Panel: straight on (u (px))."
    assert repr(figure.new_figure(1, 1)) == "A figure."


def _image_size(data: bytes) -> tuple[int, int]:
    from PIL import Image

    with Image.open(io.BytesIO(data)) as im:
        return im.size


COURSE = ["01_pinhole_projection.ipynb", "02_homography.ipynb", "03_intrinsic_calibration.ipynb",
          "03b_calibration_quality.ipynb", "04_distortion_rectification.ipynb", "05_extrinsic_calibration.ipynb"]
_IMG = re.compile(r'<img src="data:image/(png|jpeg);base64,([A-Za-z0-9+/=]+)" alt="([^"]*)"')


@pytest.mark.parametrize("name", COURSE)
def test_every_stored_figure_has_a_descriptive_alt_text_and_a_legible_size(name):
    nb = nbformat.read(str(SOLUTIONS / name), as_version=4)
    n = 0
    for i, cell in enumerate(nb.cells):
        for out in cell.get("outputs", []) if cell.cell_type == "code" else []:
            data = out.get("data", {})
            assert "image/png" not in data, f"{name} cell {i}: a bare PNG (no alt attribute can reach it)"
            found = _IMG.search(data.get("text/html", ""))
            if not found:
                continue
            n += 1
            alt = html.unescape(found.group(3))
            assert alt == data.get("text/plain"), f"{name} cell {i}: the alt attribute is not the figure's text"
            assert not alt.startswith("<") and "CourseFigure" not in alt, f"{name} cell {i}: alt text {alt!r}"
            words = alt.split()
            assert len(words) >= 10 and alt.rstrip().endswith("."), f"{name} cell {i}: alt text too thin: {alt!r}"
            w, h = _image_size(base64.b64decode(found.group(2)))
            assert h >= 150 and w / h <= 4.5, f"{name} cell {i}: a {w}x{h} figure is squeezed"
    assert n, f"{name}: no figure found"


# --- every colour the kit draws -------------------------------------------------------------------------------------

KIT = Path(figure.__file__).parent
#: synth.py paints the synthetic world (the room, the printed board, a window frame): scenery, not a mark the kit
#: draws to tell the user something
SCENERY = {"synth.py"}
#: colour maps the kit may use: perceptually uniform and readable under colour-vision deficiency (matplotlib's
#: viridis family, designed for it: van der Walt and Smith, "mpl colormaps", SciPy 2015) and grey for frames
COLOUR_MAPS = {"viridis", "magma", "magma_r", "cividis", "gray"}
_CV2_DRAWING = {"line", "circle", "rectangle", "polylines", "putText", "drawMarker", "arrowedLine", "fillPoly",
                "fillConvexPoly", "ellipse"}
_COLOUR_KEYWORDS = {"color", "colour", "c", "colors", "facecolor", "edgecolor", "foreground", "markerfacecolor",
                    "markeredgecolor", "mfc", "mec"}
_HEX = re.compile(r"#(?:[0-9a-fA-F]{6}|[0-9a-fA-F]{3})\b")


def _allowed(hex_colour: str) -> bool:
    """Of the palette, or a neutral grey (black and white included)."""
    h = hex_colour.lower()
    if len(h) == 4:
        h = "#" + "".join(ch * 2 for ch in h[1:])
    r, g, b = (h[1:3], h[3:5], h[5:7])
    return h in {c.lower() for c in figure.PALETTE.values()} or r == g == b


def _bgr_tuple(node) -> str | None:
    if isinstance(node, ast.Tuple) and len(node.elts) == 3 and all(
            isinstance(e, ast.Constant) and isinstance(e.value, int) for e in node.elts):
        b, g, r = (e.value for e in node.elts)
        return f"#{r:02x}{g:02x}{b:02x}"
    return None


def kit_colours(source: str) -> list[tuple[int, str, str]]:
    """Every colour a module's code draws with, as ``(line, what, colour)``; ``colour`` is #rrggbb or a name.

    Hex colours in any string (HTML, SVG, matplotlib), matplotlib colour keywords and format strings
    ("b+", "r-"), OpenCV drawing calls' BGR tuples, BGR tuples bound to a ``*COLOR*`` name or a ``color``
    parameter's default, and colour-map names.
    """
    from matplotlib.colors import to_hex

    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            found += [(node.lineno, "hex in a string", m.group(0)) for m in _HEX.finditer(node.value)]
        if isinstance(node, ast.Call):
            name = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
            for kw in node.keywords:
                if kw.arg in _COLOUR_KEYWORDS and isinstance(kw.value, ast.Constant) and isinstance(kw.value.value,
                                                                                                   str):
                    found.append((node.lineno, f"{name}({kw.arg}=)", to_hex(kw.value.value)))
                if kw.arg == "cmap" and isinstance(kw.value, ast.Constant):
                    found.append((node.lineno, "colour map", f"cmap:{kw.value.value}"))
            if name in ("plot", "loglog", "semilogx", "semilogy") and len(node.args) >= 2:
                fmt = node.args[-1]
                if isinstance(fmt, ast.Constant) and isinstance(fmt.value, str):
                    found += [(node.lineno, f"{name} format {fmt.value!r}", to_hex(ch))
                              for ch in re.findall(r"[bgrcmykw]", fmt.value)]
            if name in _CV2_DRAWING:
                found += [(node.lineno, f"cv2.{name}", c) for c in map(_bgr_tuple, node.args) if c]
        if isinstance(node, ast.Assign) and _bgr_tuple(node.value) and any(
                "COLO" in getattr(t, "id", "").upper() for t in node.targets):
            found.append((node.lineno, "a *COLOR* constant", _bgr_tuple(node.value)))
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            args = node.args.args[len(node.args.args) - len(node.args.defaults):] + node.args.kwonlyargs
            defaults = node.args.defaults + [d for d in node.args.kw_defaults]
            for a, d in zip(args, defaults):
                if a.arg in ("color", "colour") and _bgr_tuple(d):
                    found.append((node.lineno, f"{node.name}({a.arg}=) default", _bgr_tuple(d)))
        if isinstance(node, ast.Subscript) and isinstance(node.value, ast.Attribute) and node.value.attr == "colormaps":
            found.append((node.lineno, "colour map", f"cmap:{getattr(node.slice, 'value', '?')}"))
    return found


def test_the_colour_scan_itself_finds_what_the_kit_used_to_draw():
    old = '''
GREEN, GREY, RED = "#2e9d46", "#9aa0a6", "#c0392b"
def draw_ground_grid(img, H, *, color=(0, 255, 0)):
    cv2.polylines(small, [hull], True, (0, 200, 0), 1)
    ax.plot(K[0, 2], K[1, 2], "b+", ms=12)
    ax.scatter([0], [0], [0], c="r", s=15)
    ax.imshow(x, cmap="jet")
'''
    colours = {c for _, _, c in kit_colours(old)}
    assert {"#2e9d46", "#c0392b", "#00ff00", "#00c800", "#0000ff", "#ff0000", "cmap:jet"} <= colours
    assert not _allowed("#2e9d46") and _allowed("#9AA09A".replace("A09A", "9A9A")) and _allowed("#D55E00")


def test_every_colour_the_kit_draws_is_of_the_palette():
    bad = []
    n = 0
    for path in sorted(KIT.rglob("*.py")):
        if path.name in SCENERY:
            continue
        for line, what, colour in kit_colours(path.read_text(encoding="utf-8")):
            n += 1
            ok = colour[5:] in COLOUR_MAPS if colour.startswith("cmap:") else _allowed(colour)
            if not ok:
                bad.append(f"{path.relative_to(KIT)}:{line} {what} {colour}")
    assert n > 30, f"the scan found only {n} colours: it no longer sees the kit's drawing code"
    assert not bad, "colours outside the palette (dtscal_lib/figure.py PALETTE, or a grey):\n" + "\n".join(bad)


@pytest.mark.parametrize("deficiency", sorted(MACHADO))
def test_the_live_tools_good_and_bad_colours_are_the_palettes_and_stay_apart(deficiency):
    from dtscal_lib.ui import render

    verdict = {v: render.verdict_html(SimpleNamespace(verdict=v, findings=[])) for v in ("good", "doubtful", "bad")}
    shown = {**verdict, "full": render.bars_html([SimpleNamespace(name="X", progress=1.0, full=True)]),
             "ok": render.message_html("saved", "ok"), "error": render.message_html("failed", "error"),
             "chart": render.error_chart_svg([0.2, 0.9, 0.3], dropped_positions=[1])}
    used = {k: set(_HEX.findall(v)) for k, v in shown.items()}
    off = {k: sorted(c for c in cs if not _allowed(c)) for k, cs in used.items()}
    assert not any(off.values()), f"the live tools draw outside the palette: {off}"
    palette = {c.lower() for c in figure.PALETTE.values()}
    (good,), (bad,) = ({c for c in used[v] if c.lower() in palette} for v in ("good", "bad"))  # the verdict's colour
    assert _delta_e(good, bad, MACHADO[deficiency]) >= MIN_DELTA_E, (good, bad)


def test_the_ground_grid_is_drawn_in_a_palette_colour():
    from dtscal_lib import duckietown as dt
    from dtscal_lib.ground import draw_ground_grid

    out = draw_ground_grid(np.zeros((480, 640), np.uint8), dt.default_H(), spacing=0.05)
    drawn = out.reshape(-1, 3).astype(int)
    # anti-aliasing blends the lines' colour with the black frame; where a line covers a whole pixel it is pure
    b, g, r = drawn[np.argmax(drawn.sum(axis=1))]
    assert _allowed(f"#{r:02x}{g:02x}{b:02x}"), f"the grid is drawn in #{r:02x}{g:02x}{b:02x}"
