"""The data behind ``detect.GRID_TOLERANCE_PX`` / ``GRID_TOLERANCE_FRACTION`` (the grid check of a found board).

For every real photograph of ``data/real/`` (26 views, 9x6 inner corners), flat and bent smoothly,
prints the largest distance of an inner corner from the quadratic through its 8 neighbours
(``detect.grid_jump``) in pixels and in squares, the outer ring's largest as a fraction of its
tolerance (``detect.grid_tolerance``), the worst corner against the truth, and how many boards the
former check (a homography through the 8 neighbours, tolerance max(0.75 px, 0.1 square)) and the
kit's detector refuse.

Bends (``cv2.remap``; the truth is the flat detection carried through the field):

* ``curl``: the photograph scaled by 0.6 (squares of 12-23 px, as Duckietown's 17 mm squares on the
  floor), displaced by ``(0.15 A u^3, A u^2)`` with ``u`` the distance from the board's centre column
  in half board widths: a print curling up at its two sides, ``A`` = 6 and 12 px;
* ``wave``: full size, sines of 300 px wavelength and 5 px amplitude in x and y.

Run: ``.venv/bin/python benchmarks/grid_tolerance.py`` (about a minute).
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dtscal_lib import detect as D  # noqa: E402
from dtscal_lib.detect.grid import _local_square  # noqa: E402
from dtscal_lib.boards import parse_board  # noqa: E402

REAL = Path(__file__).resolve().parents[1] / "data" / "real" / "opencv-samples"
B = parse_board("9x6", 0.03)


def warp(img, d):
    h, w = img.shape
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    dx, dy = d(x, y)
    return cv2.remap(img, (x + dx).astype(np.float32), (y + dy).astype(np.float32), cv2.INTER_CUBIC,
                     borderMode=cv2.BORDER_REPLICATE)


def carried(d, p):
    q = p.copy()
    for _ in range(60):
        dx, dy = d(q[:, 0], q[:, 1])
        q = p - np.column_stack([dx, dy])
    return q


def curl(c, amp):
    cx, half = c[:, 0].mean(), np.ptp(c[:, 0]) / 2

    def d(x, y):
        u = (x - cx) / half
        return 0.15 * amp * u ** 3, amp * u ** 2
    return d


def wave(amp, wavelength=300.0, phase=0.0):
    k = 2 * np.pi / wavelength

    def d(x, y):
        return (amp * np.sin(k * x + phase) * np.cos(0.7 * k * y),
                amp * np.sin(k * y + 1.3 * phase) * np.cos(0.6 * k * x))
    return d


def row(name, cases):
    jumps, fracs, outer, old_refused, refused, worst = [], [], [], 0, 0, 0.0
    for img, truth in cases:
        g = truth.reshape(B.rows, B.cols, 2)
        sq = float(min(np.linalg.norm(np.diff(g, axis=1), axis=2).min(),
                       np.linalg.norm(np.diff(g, axis=0), axis=2).min()))
        inner = np.zeros((B.rows, B.cols), bool)
        inner[1:-1, 1:-1] = True
        old_refused += bool(np.nanmax(D.grid_disagreement(truth, B)[inner.ravel()]) > max(0.75, 0.1 * sq))
        det = D.detect_board_still(img, B)
        if not det.found:
            refused += 1
            continue
        j = D.grid_jump(det.corners, B)
        jumps.append(j[inner.ravel()].max())
        fracs.append((j / _local_square(det.corners, B))[inner.ravel()].max())
        outer.append((j / D.grid_tolerance(det.corners, B))[~inner.ravel()].max())
        worst = max(worst, float(np.linalg.norm(det.corners - truth, axis=1).max()))
    print(f"{name:20s} views {len(cases):3d}  inner jump max {max(jumps):.2f} px ({max(fracs):.3f} square), "
          f"outer ring at most {max(outer):.2f} of its tolerance; refused: former check {old_refused:2d}, "
          f"kit {refused:2d}; worst corner vs truth {worst:.2f} px")


def main():
    flat, curled6, curled12, waved = [], [], [], []
    all_jumps = []
    for f in sorted(REAL.glob("*/*.jpg")):
        img = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        c = D.detect_board_still(img, B).corners
        flat.append((img, c))
        all_jumps.append(D.grid_jump(c, B).reshape(B.rows, B.cols)[1:-1, 1:-1].ravel())
        small = cv2.resize(img, None, fx=0.6, fy=0.6, interpolation=cv2.INTER_AREA)
        cs = D.detect_board_still(small, B).corners
        for amp, out in ((6.0, curled6), (12.0, curled12)):
            d = curl(cs, amp)
            out.append((warp(small, d), carried(d, cs)))
        for ph in (0.0, 2.0):
            d = wave(5.0, phase=ph)
            waved.append((warp(img, d), carried(d, c)))
    j = np.concatenate(all_jumps)
    print(f"flat inner corners {len(j)}: jump median {np.median(j):.3f} px, 99th percentile "
          f"{np.percentile(j, 99):.3f}, max {j.max():.3f}; corner noise ~ median / (1.5 * 1.177) = "
          f"{np.median(j) / 1.5 / 1.1774:.3f} px per coordinate")
    row("flat", flat)
    row("curl 6 px (x0.6)", curled6)
    row("curl 12 px (x0.6)", curled12)
    row("wave 5 px / 300 px", waved)


if __name__ == "__main__":
    main()
