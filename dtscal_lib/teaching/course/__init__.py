"""What the course notebooks use: one fallback contract, one figure convention, figures by concept.

Notebooks stay thin: they explain, hold the student's functions and their checks, and call
this package for plumbing and pictures::

    from dtscal_lib.teaching import course
    project = course.use_or_fallback(project_points, stand_in, check=check_project_points,
                                     fallback_name="the kit's camera.project_points")
    course.projection_figure(project, K, poses, titles)      # a figure: the cell's last value

Modules, each named after the concept it holds:

* :mod:`~dtscal_lib.teaching.course.fallback`: the student's function or the kit's stand-in, said once
* :mod:`~dtscal_lib.teaching.course.figure` (:mod:`dtscal_lib.figure`): pyplot-free figures shown as small PNGs
* :mod:`~dtscal_lib.teaching.course.session`: the recorded session through :mod:`dtscal_lib.datasets`
* :mod:`~dtscal_lib.teaching.course.projection`, :mod:`~dtscal_lib.teaching.course.homography`,
  :mod:`~dtscal_lib.teaching.course.calibration`, :mod:`~dtscal_lib.teaching.course.residuals`,
  :mod:`~dtscal_lib.teaching.course.distortion`, :mod:`~dtscal_lib.teaching.course.ground`: figures and experiments
* :mod:`~dtscal_lib.teaching.workspace`: the student's workspace copy and its updates
"""

from .calibration import (degradation_experiment, intrinsics_table, plot_board_poses, pose_from_homography_opencv,
                          show_views)
from .distortion import compare_alpha, distort_image, grid_image, plot_distortion_field, plot_undistortion_error
from .fallback import Fallback, banner, notebook_function, use_or_fallback
from .figure import CourseFigure, draw_board, image_axes, new_figure, show_image, show_images
from .ground import ground_error_mm, ground_error_report, plot_ground_layout, show_ground_result
from .homography import (conditioning_experiment, conditioning_figure, conditioning_summary, fronto_parallel_view,
                         residual_figure, unnormalized_dlt, warp_figure)
from .projection import look_at_pose, pinhole_explorer, projection_figure, render_board_image, sample_views
from .residuals import plot_reprojection, reprojection_residuals, rms
from .session import (ExtrinsicCapture, IntrinsicViews, board_homographies, distorted_board_frame, find_corners,
                      load_extrinsic_capture, load_intrinsic_views)

__all__ = [
    "Fallback", "banner", "notebook_function", "use_or_fallback",
    "CourseFigure", "draw_board", "image_axes", "new_figure", "show_image", "show_images",
    "ExtrinsicCapture", "IntrinsicViews", "board_homographies", "distorted_board_frame", "find_corners",
    "load_extrinsic_capture", "load_intrinsic_views",
    "look_at_pose", "pinhole_explorer", "projection_figure", "render_board_image", "sample_views",
    "conditioning_experiment", "conditioning_figure", "conditioning_summary", "fronto_parallel_view",
    "residual_figure", "unnormalized_dlt", "warp_figure",
    "degradation_experiment", "intrinsics_table", "plot_board_poses", "pose_from_homography_opencv", "show_views",
    "plot_reprojection", "reprojection_residuals", "rms",
    "compare_alpha", "distort_image", "grid_image", "plot_distortion_field", "plot_undistortion_error",
    "ground_error_mm", "ground_error_report", "plot_ground_layout", "show_ground_result",
]
