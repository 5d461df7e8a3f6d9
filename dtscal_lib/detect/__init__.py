"""Checkerboard corner detection that stays fast when no board is in view.

ROS's ``camera_calibration`` runs OpenCV's classic ``findChessboardCorners`` (flags
``ADAPTIVE_THRESH | NORMALIZE_IMAGE | FAST_CHECK``) on every full frame. On a frame that
holds a board it answers in a few milliseconds, but on a cluttered frame with many
dark quadrilaterals (shelves, boxes, tiled floors, textured noise) its fast check lets
the frame through and it then tries about fifty thresholds and dilations before giving
up: 100-250 ms per 640x480 frame, several times the camera's frame period.

:func:`detect_board` puts a cheap, board-specific test in front of the same detector:

1. **Saddle points** (:func:`find_saddles`). On a half-size, slightly blurred image the
   Hessian of the intensity is computed with Sobel filters; inner corners of a
   checkerboard are saddles (``fxy^2 - fxx*fyy`` large) and, going from one corner to its
   neighbour along a row or column, the saddle's principal direction turns by 90 degrees
   (the dark diagonal becomes the light one).
2. **Grid clusters** (:func:`board_regions`). Saddles are linked to nearby saddles of
   similar strength whose principal direction differs by about 90 degrees, at most twice as
   far as the second-nearest saddle (mutual links only; the second-nearest, not the nearest:
   a board whose outer squares are cut narrow has saddles on its physical edge less than half
   a square from its outer corners); a connected cluster with at least 80 % as many saddles as the board has
   inner corners is a board candidate (its box is tried together with sizeable clusters
   right next to it, as a board seen edge-on can split into pieces, then alone). Clutter
   rarely produces such clusters: blocky texture gives many saddles, but with random
   polarity, so its clusters stay small.
3. **The grid straight from the saddles** (:func:`_saddle_lattice`): the cluster's saddles are walked as a
   grid (each corner's local grid vectors predict its neighbours); where they form exactly the board's
   ``rows x cols`` window, with only weaker saddles one step outside it (the printed edge, not more board),
   those are the raw corners and OpenCV's classic detector is not run at all (on most views:
   ``benchmarks/README.md``, "The detector's measurements").
   Otherwise, or where the refinement's checks reject that start:
   **classic detection on the candidate region only**: ``findChessboardCorners`` on the
   cluster's bounding box plus a margin (ROS's flags without ``FAST_CHECK``, whose quick
   test rejects many tightly cropped boards; small regions are tried again at twice the
   size). The live detector bounds this step's work (the classic detector answers in 1-5 ms
   where it finds a board, but spends 10-35 ms per region where it does not, typically on a
   board cut by the image edge, which the border rule rejects anyway): a region nearly the
   same as one already tried is skipped, a cluster of large squares (saddle spacing >= 20 px)
   is searched at full size only if a search at half size finds the board, and a small
   region touching the image edge gets no 2x retry.
   :func:`detect_board_still` then makes every skipped attempt where the live path found nothing.
4. **Sub-pixel refinement that stays inside each corner's own squares**
   (:func:`refine_corners_checked`). ROS refines every corner with one ``cornerSubPix``
   window of half the smallest corner spacing; on real boards (outer squares cut narrow,
   a printed outline, the board's edge or clutter close by) that window reaches past the
   corner's four squares and the outer corners converge on the edge, pixels away. Here each
   corner gets its own window (:func:`corner_windows`), the outer ring is restarted from the
   inner corners' local homography where it disagrees, each corner is checked against the
   quadratic through its 8 grid neighbours (:func:`grid_jump`, which a smoothly curled print
   passes; re-refined with half the window, or the board is found but rejected as
   ``"inconsistent_grid"``, naming the corner), and a corner off a smooth (cubic)
   grid through the others goes back to the detector's position or is dropped with the view.
   Last, every corner is polished once more on the image smoothed by a 1 px Gaussian
   (:func:`polish_corners`), which removes ``cornerSubPix``'s few-hundredths-of-a-pixel bias on
   sharp edges.

A frame without any candidate costs only steps 1-2; see ``benchmarks/README.md`` and
``benchmarks/bench_detect.py`` for the measured figures and ratios against the ROS call,
which :func:`detect_board_ros` reproduces as the baseline.

Corner order follows ROS: OpenCV's row-major order (``cols`` corners per row), made to
run top to bottom (if the first corner is below the last, the order is reversed). This
module also fixes the handedness first (each row is reversed if the grid would appear
mirrored), so the same physical corner keeps its index while the board turns smoothly.

ROS rules kept: a detection with any corner within ``border_margin`` (8) pixels of the
image edge is rejected (reason ``"at_border"``).

One step per module: :mod:`.saddles` (steps 1-2), :mod:`.lattice` (3, from the saddles), :mod:`.classic` (3, OpenCV's
detector on the regions, and the public detectors), :mod:`.refine` (4), :mod:`.grid` (4's grid checks),
:mod:`.order` (the corners' order), :mod:`.frame` (:class:`Detection`, input and drawing). The refusal tolerances
are rows of :mod:`dtscal_lib.limits`.
"""

from __future__ import annotations

import cv2  # noqa: F401  (tests spy on cv2.findChessboardCorners through this name)

from ..limits import GRID_TOLERANCE_FRACTION, GRID_TOLERANCE_PX, SMOOTH_GRID_TOLERANCE
from .classic import (HALF_SIZE_SPACING, REGION_FLAGS, ROS_FLAGS, UPSCALE_REGION_SIDE, detect_board,
                      detect_board_ros, detect_board_still)
from .frame import REASON_AT_BORDER, REASON_INCONSISTENT, REASON_NO_BOARD, Detection, draw_detection, to_gray
from .grid import grid_disagreement, grid_jump, grid_rejection, grid_residuals, grid_tolerance
from .lattice import LATTICE_REACH, LATTICE_RING_RATIO, LATTICE_RING_SIDE, LATTICE_RING_STRONG
from .order import order_corners
from .refine import (INNER_REACH, MIN_ISOTROPY, MIN_WINDOW, OUTER_SQUARE_FRACTION, POLISH_MAX_MOVE_PX,
                     REFINE_CRITERIA, REFINE_SIGMA, SUBPIX_CRITERIA, WINDOW_MARGIN_PX, corner_isotropy,
                     corner_misfit, corner_windows, polish_corners, refine_corners, refine_corners_checked,
                     refine_image, subpix_radius)
from .saddles import MERGE_REACH, MIN_REGION_SIDE, board_regions, find_saddles

__all__ = [
    "Detection", "detect_board", "detect_board_ros", "detect_board_still", "draw_detection", "to_gray",
    "order_corners", "board_regions", "find_saddles", "subpix_radius", "refine_corners", "refine_corners_checked",
    "polish_corners", "refine_image", "corner_windows", "corner_misfit", "corner_isotropy", "grid_disagreement",
    "grid_jump", "grid_tolerance", "grid_residuals", "grid_rejection",
    "REASON_NO_BOARD", "REASON_AT_BORDER", "REASON_INCONSISTENT", "ROS_FLAGS", "REGION_FLAGS", "SUBPIX_CRITERIA",
    "REFINE_CRITERIA", "REFINE_SIGMA", "POLISH_MAX_MOVE_PX", "OUTER_SQUARE_FRACTION", "INNER_REACH",
    "WINDOW_MARGIN_PX", "MIN_ISOTROPY", "MIN_WINDOW", "MIN_REGION_SIDE", "MERGE_REACH", "UPSCALE_REGION_SIDE",
    "HALF_SIZE_SPACING", "LATTICE_REACH", "LATTICE_RING_RATIO", "LATTICE_RING_SIDE", "LATTICE_RING_STRONG",
    "GRID_TOLERANCE_PX", "GRID_TOLERANCE_FRACTION", "SMOOTH_GRID_TOLERANCE",
]
