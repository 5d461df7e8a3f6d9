"""ipywidgets applications of the kit: the live intrinsic calibrator and the live extrinsic tool.

Each tool keeps all of its state in one object; the library functions it calls stay stateless.

* :class:`LiveCalibrator` - coverage bars, CALIBRATE in the background, COMMIT, SAVE/load;
* :class:`LiveExtrinsics` - the ground homography fitted on every frame, best fit kept, a
  validation view (grid and bird's-eye).
"""

from .extrinsic import LiveExtrinsics
from .intrinsic import LiveCalibrator

__all__ = ["LiveCalibrator", "LiveExtrinsics"]
