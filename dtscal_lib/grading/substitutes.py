"""Stand-ins for exercise functions that other exercise functions call: one bug, one charge.

When a graded function calls another exercise function of its notebook (``undistort_normalized``
and ``rectification_maps`` call ``distort_normalized``, ``estimate_homography`` may call
``apply_homography``, ``intrinsics_from_homographies`` calls ``intrinsic_constraints``), the
grader runs its checks twice: once with the student's own callee, once with the callee
replaced by the stand-in below (see :func:`dtscal_lib.grading.grade.grade_file`). It keeps the
better of the two, says so in the feedback, and says when the student's own callee changes
the result, so a wrong ``distort_normalized`` costs only ``distort_normalized``.

Each stand-in is self-contained (imports inside, numpy only, no OpenCV and no solution code:
the source is executed in the sandbox, where the student's code can read it) and follows the
contract stated in the notebooks. They are checked against OpenCV in the tests.
"""

from __future__ import annotations

import inspect

from ..exercise_rules import STAND_IN_CALLEES


def apply_homography(H, pts):
    import numpy

    p = numpy.asarray(pts, dtype=numpy.float64).reshape(-1, 2)
    q = numpy.column_stack([p, numpy.ones(len(p))]) @ numpy.asarray(H, dtype=numpy.float64).T
    return q[:, :2] / q[:, 2:]


def intrinsic_constraints(H):
    import numpy

    H = numpy.asarray(H, dtype=numpy.float64)

    def v(i, j):
        a, b = H[:, i], H[:, j]
        return numpy.array([a[0] * b[0], a[0] * b[1] + a[1] * b[0], a[1] * b[1],
                            a[2] * b[0] + a[0] * b[2], a[2] * b[1] + a[1] * b[2], a[2] * b[2]])

    return numpy.vstack([v(0, 1), v(0, 0) - v(1, 1)])


def distort_normalized(xy, dist):
    import numpy

    xy = numpy.asarray(xy, dtype=numpy.float64).reshape(-1, 2)
    k1, k2, p1, p2, k3 = numpy.asarray(dist, dtype=numpy.float64).ravel()[:5]
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    radial = 1.0 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
    return numpy.column_stack([x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
                               y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y])


def board_ground_points(cols, rows, square, x0, y0):
    import numpy

    k = numpy.arange(int(cols) * int(rows))
    return numpy.column_stack([x0 + (k // int(cols)) * float(square), y0 + (k % int(cols)) * float(square)])


#: the callees that have a stand-in
SUBSTITUTES = STAND_IN_CALLEES


def source(name: str) -> str:
    """The stand-in's source, to run in the sandbox in place of the student's ``name``."""
    if name not in SUBSTITUTES:
        raise KeyError(name)
    return inspect.getsource(globals()[name])
