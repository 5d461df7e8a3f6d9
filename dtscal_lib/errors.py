"""Exception types of the kit.

Every error the kit raises on bad input derives from :class:`DtscalError` (itself a
``ValueError``), and its message says what was wrong and what to do about it.
"""

from __future__ import annotations


class DtscalError(ValueError):
    """Base class: bad input that the user can fix."""


class CalibrationError(DtscalError):
    """Degenerate or inconsistent calibration input (too few views, NaN, ...)."""


class CalibrationFileError(DtscalError):
    """A calibration YAML file is missing, malformed, hostile or implausible.

    The message names the file and, where it applies, the field.
    """


class SourceError(DtscalError):
    """A camera source (bag, video, folder, topic) cannot be opened or read."""


class FrameError(DtscalError):
    """One frame cannot be used (corrupt JPEG, empty, wrong size).

    Pipelines count and skip these; they never stop a stream.
    """

    def __init__(self, reason: str, message: str):
        super().__init__(message)
        #: short machine-readable reason, used as a key in rejection counts
        self.reason = reason


class ImplausibleCalibrationError(CalibrationError):
    """A calibration was computed but the kit does not believe it; nothing was written over the robot's file.

    ``doubts`` lists the reasons (each says what to do). ``dtscal`` exits with code 3.
    """

    def __init__(self, message: str, doubts: list[str]):
        super().__init__(message)
        self.doubts = list(doubts)
