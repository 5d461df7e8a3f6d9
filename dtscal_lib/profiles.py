"""Duckietown's robots: what the extrinsic calibration expects of each one's camera and board.

Two robots, each from Duckietown's own files (``duckietown.md``; lib-dt-computer-vision's
``src/dt_computer_vision/camera/calibration/extrinsics/boards.py`` and its DD24 assets, kept in
``data/duckietown/dd24/`` with their source named):

* **duckiebot**: the 7x5-corner board of 31 mm squares, its outer corner at x = 0.160 m, y = -0.124 m
  (``CalibrationBoard8by6``), a 640x480 camera; the camera's pose limits are the fleet's
  (:data:`dtscal_lib.limits.GROUND_CAMERA_LIMITS`); ``H[1][2] > 0`` is Duckietown's "corrupt" rule; the printed
  pattern's colours are known (the corner square nearest the robot on its right is white).
* **dd24** (the Duckiedrone DD24): the 7x5-corner board of 17 mm squares, its outer corner at x = 0.25 m,
  y = -0.080 m (``CalibrationBoardDD24``), a portrait camera (its intrinsic file: 240x320, photographs 480x640);
  the camera about 5.6 cm above the board and 47 degrees down, so the image's top-left pixel lies below the
  horizon, ahead on the left, and ``H[1][2] > 0`` is its normal sign. Its A4 print
  (``camera_calibration_pattern_A4_rev0824``) has the Duckiebot's convention, read off Duckietown's real DD24
  photograph (``duckietown.md``): the corner square nearest the drone on its right is white, so a mirrored DD24
  frame is refused as a mirrored Duckiebot frame is.

The board implies the profile (:func:`profile_for`); ``--robot-type`` overrides it.
"""

from __future__ import annotations

from dataclasses import dataclass

from .boards import Board
from .errors import DtscalError
from .limits import LIMITS

__all__ = ["RobotProfile", "PROFILES", "DUCKIEBOT", "DD24", "profile_for"]


@dataclass(frozen=True)
class RobotProfile:
    """One robot's extrinsic set-up: its board and place, its camera's expected pose, its file conventions."""

    name: str
    board: Board
    #: x (forward) of the board's near row of inner corners and y of its right-most column, metres
    near_row_x: float
    right_column_y: float
    #: (width, height) of the camera's frames
    image_size: tuple[int, int]
    #: the camera's plausible pose over the ground (rows of :mod:`dtscal_lib.limits`)
    height_m: tuple[float, float]
    pitch_down_deg: tuple[float, float]
    #: fx / image width of the robots' real intrinsic files (a file outside loads with a warning)
    fx_per_width: tuple[float, float]
    #: Duckietown's "H[1][2] > 0 is corrupt" rule applies (the Duckiebot's; not the DD24's)
    corrupt_rule: bool
    #: the printed pattern's colours are known (the mirror check is made)
    colours_known: bool

    @property
    def ground_limits(self) -> dict:
        """The pose limits in the form of :data:`dtscal_lib.limits.GROUND_CAMERA_LIMITS`."""
        return {"height_m": self.height_m, "pitch_down_deg": self.pitch_down_deg,
                "abs_yaw_deg": LIMITS["camera_yaw"].value, "axis_ratio": LIMITS["axis_ratio"].value,
                "axis_angle_error_deg": LIMITS["axis_angle_error"].value}


#: Duckietown's Duckiebot (boards.py ``CalibrationBoard8by6``: 0.160 + 0.031, -0.124 + 0.031)
DUCKIEBOT = RobotProfile("duckiebot", Board(7, 5, 0.031), 0.191, -0.093, (640, 480),
                         LIMITS["camera_height"].value, LIMITS["camera_pitch"].value,
                         LIMITS["robot_fx_per_width"].value, corrupt_rule=True, colours_known=True)
#: Duckietown's Duckiedrone DD24 (boards.py ``CalibrationBoardDD24``: 0.25 + 0.017, -0.080 + 0.017)
DD24 = RobotProfile("dd24", Board(7, 5, 0.017), 0.267, -0.063, (480, 640),
                    LIMITS["dd24_camera_height"].value, LIMITS["dd24_camera_pitch"].value,
                    LIMITS["dd24_fx_per_width"].value, corrupt_rule=False, colours_known=True)

PROFILES: dict[str, RobotProfile] = {p.name: p for p in (DUCKIEBOT, DD24)}


def profile_for(board: Board | None = None, robot_type: str | None = None) -> RobotProfile:
    """The robot a calibration is for: ``robot_type`` when given, else the one whose board ``board`` is
    (the DD24's 17 mm squares; any other board is the Duckiebot's set-up)."""
    if robot_type is not None:
        key = str(robot_type).strip().lower()
        if key not in PROFILES:
            raise DtscalError(f"unknown robot type {robot_type!r}; use one of: {', '.join(PROFILES)}")
        return PROFILES[key]
    if board is not None and (board.cols, board.rows) == (DD24.board.cols, DD24.board.rows) \
            and abs(board.square - DD24.board.square) < 1e-9:
        return DD24
    return DUCKIEBOT


def profile_for_image(width: int, height: int) -> RobotProfile:
    """The robot whose camera gives frames of this shape: portrait frames are the DD24's."""
    return DD24 if height > width else DUCKIEBOT
