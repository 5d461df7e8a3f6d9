"""Figures everyone can read: a colour-blind-safe palette, legible sizes, and an alt text on every stored figure.

The palette is checked by simulating colour-vision deficiency with the matrices of Machado, Oliveira and
Fernandes, "A physiologically-based model for simulation of color vision deficiency", IEEE TVCG 15(6), 2009
(severity 1.0, applied to linear RGB), and measuring the CIE76 colour difference (Delta E*ab) of every pair in
CIELAB. matplotlib's own red and green ("tab:red", "tab:green") are 7.3 apart under deuteranopia: a pair a
deuteranope can barely tell apart; every pair of the kit's palette must stay at least 15 apart.
"""

from __future__ import annotations

import base64
import itertools
import struct

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


def _png_size(data: bytes) -> tuple[int, int]:
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


COURSE = ["01_pinhole_projection.ipynb", "02_homography.ipynb", "03_intrinsic_calibration.ipynb",
          "04_distortion_rectification.ipynb", "05_extrinsic_calibration.ipynb"]


@pytest.mark.parametrize("name", COURSE)
def test_every_stored_figure_has_a_descriptive_alt_text_and_a_legible_size(name):
    nb = nbformat.read(str(SOLUTIONS / name), as_version=4)
    n = 0
    for i, cell in enumerate(nb.cells):
        for out in cell.get("outputs", []) if cell.cell_type == "code" else []:
            data = out.get("data", {})
            if "image/png" not in data:
                continue
            n += 1
            alt = data.get("text/plain", "")
            assert not alt.startswith("<") and "CourseFigure" not in alt, f"{name} cell {i}: alt text {alt!r}"
            words = alt.split()
            assert len(words) >= 10 and alt.rstrip().endswith("."), f"{name} cell {i}: alt text too thin: {alt!r}"
            w, h = _png_size(base64.b64decode(data["image/png"]))
            assert h >= 150 and w / h <= 4.5, f"{name} cell {i}: a {w}x{h} figure is squeezed"
    assert n, f"{name}: no figure found"
