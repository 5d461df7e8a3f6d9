"""Self-checks that exercise notebooks call after each student function.

A check runs a student's function on cases with known answers (ground truth from the
synthetic camera, or OpenCV), never against the solution code, and prints what passed,
what failed and a hint. A function that still raises ``NotImplementedError`` is reported
as "not implemented yet" and the notebook carries on.

The checks live in one module per concept (``projection``, ``homography``, ``zhang``,
``distortion``, ``ground``), all built on
:func:`run_check`:

>>> def check_double(fn):
...     return run_check("double", fn, [
...         Case("doubles 2", lambda f: expect_close(f(2), 4, 0, "f(2)"), hint="multiply by 2"),
...     ])
"""

from __future__ import annotations

from .core import (
    FAIL,
    NOT_IMPLEMENTED,
    PASS,
    Case,
    CaseResult,
    CheckFailed,
    Report,
    SelfCheckFailed,
    expect_close,
    expect_shape,
    num,
    nums,
    run_check,
    strict,
)

# The notebooks import every check from here (``from dtscal_lib.teaching.selfcheck import check_...``).
from .projection import check_project_points  # noqa: E402
from .homography import check_apply_homography, check_estimate_homography  # noqa: E402
from .zhang import (  # noqa: E402
    check_extrinsics_from_homography,
    check_intrinsic_constraints,
    check_intrinsics_from_homographies,
)
from .distortion import (  # noqa: E402
    check_distort_normalized,
    check_rectification_maps,
    check_undistort_normalized,
    opencv_distort,
)
from .ground import check_board_ground_points, check_camera_height_pitch, check_pixel_to_ground  # noqa: E402
from .practice import (  # noqa: E402
    check_coverage,
    check_next_board_move,
    check_per_view_rms,
    check_picture_difference,
    check_tilt_needed,
    check_worst_views,
)
from .predict import Prediction, check_prediction, predict_choice, predict_number, predict_points  # noqa: E402
