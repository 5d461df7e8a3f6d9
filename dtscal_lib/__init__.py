"""dtscal: a camera-calibration teaching kit for Duckietown courses.

The most used pieces are importable from the package itself::

    from dtscal_lib import calibrate, CameraModel, DUCKIETOWN_BOARD, detect_board

See the README for the architecture; each module's docstring says what it holds.
"""

from .boards import DUCKIETOWN_BOARD, Board, ground_points, parse_board
from .calibration import CalibrationResult, calibrate
from .camera import CameraModel
from .detect import Detection, detect_board
from .errors import CalibrationError, CalibrationFileError, DtscalError, FrameError, SourceError

__version__ = "0.1.0"

__all__ = [
    "Board", "DUCKIETOWN_BOARD", "ground_points", "parse_board",
    "CalibrationResult", "calibrate", "CameraModel", "Detection", "detect_board",
    "DtscalError", "CalibrationError", "CalibrationFileError", "FrameError", "SourceError",
]
