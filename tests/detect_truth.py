"""Ground-truth corners put in the detector's canonical order WITHOUT the detector's code.

The detector (``dtscal_lib.detect.order_corners``) promises this order; here it is derived
again from the board pose, so that an ordering bug in the detector cannot grade itself:

1. Start from the board's own order: corner ``k`` is the object point
   ``(k % cols, k // cols) * square`` (``Board.object_points``), as projected by the renderer.
2. Handedness, from the pose: OpenCV's board frame has x along a row, y down the columns and
   z into the board. Seen from the front (z pointing away from the camera, i.e. along the
   viewing ray to the board centre) the rows step right-handedly in the image (x right,
   y down); seen from behind the image is a mirror image, and each row is reversed.
3. Rows top to bottom (ROS's rule for a non-square board): if the first corner is lower in
   the image than the last one, the whole order is reversed (a 180-degree turn of the grid).

Square boards (where ROS also turns by 90 degrees) are not covered: the tests use 7x5 and 9x6.
"""

from __future__ import annotations

import cv2
import numpy as np


def canonical_truth(corners, rvec, tvec, board) -> np.ndarray:
    """(N, 2) true corners in the detector's canonical order (see the module docstring)."""
    assert board.rows != board.cols, "square boards are not covered by this helper"
    c = np.asarray(corners, dtype=np.float64).reshape(board.rows, board.cols, 2)
    rv = np.asarray(rvec, dtype=np.float64).reshape(-1)
    R = cv2.Rodrigues(rv)[0] if rv.size == 3 else rv.reshape(3, 3)
    t = np.asarray(tvec, dtype=np.float64).reshape(3)
    centre = R @ np.array([(board.cols - 1) * board.square / 2, (board.rows - 1) * board.square / 2, 0.0]) + t
    if float(R[:, 2] @ centre) < 0:  # z axis toward the camera: the back of the board is seen
        c = c[:, ::-1]
    if c[0, 0, 1] > c[-1, -1, 1]:
        c = c[::-1, ::-1]
    return np.ascontiguousarray(c.reshape(-1, 2))


def truth_in_detector_order(case) -> np.ndarray:
    """:func:`canonical_truth` of anything with ``corners``, ``rvec``, ``tvec`` and ``board``."""
    return canonical_truth(case.corners, case.rvec, case.tvec, case.board)
