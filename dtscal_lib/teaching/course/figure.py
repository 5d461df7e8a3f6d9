"""The course's figures follow the kit's one figure convention, :mod:`dtscal_lib.figure` (re-exported here).

The convention lives in the library (the ``--report`` figures use it too); the teaching layer imports it
from there, never the other way round.
"""

from ...figure import (ARROW_COLOR, BAD_COLOR, BOARD_COLOR, DPI, GOOD_COLOR, GREY, OTHER_COLOR, PALETTE,  # noqa: F401
                      PHOTO_DPI, PHOTO_MIN_PX, PHOTO_PANEL_IN, TRUTH_COLOR, WARN_COLOR, CourseFigure, bgr, describe,
                      draw_board, figure_html, image_axes, new_figure, outlined, png_bytes, show_image, show_images)
from ...figure import __all__  # noqa: F401
