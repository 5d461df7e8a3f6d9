"""The course's figures follow the kit's one figure convention, :mod:`dtscal_lib.figure` (re-exported here).

The convention lives in the library (the ``--report`` figures use it too); the teaching layer imports it
from there, never the other way round.
"""

from ...figure import (ARROW_COLOR, BOARD_COLOR, DPI, OTHER_COLOR, PALETTE, PHOTO_DPI, TRUTH_COLOR,  # noqa: F401
                      CourseFigure, describe, draw_board, image_axes, new_figure, png_bytes, show_image, show_images)
from ...figure import __all__  # noqa: F401
