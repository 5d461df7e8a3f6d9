"""Exception types of the kit, and its one rule for saying that something failed.

Every error the kit raises on bad input derives from :class:`DtscalError` (itself a
``ValueError``), and its message says what was wrong and what to do about it.

The rule
--------
* **A normal answer about one picture is a value, not an exception.** "No board in this
  frame", "the board touches the border", "a corner disagrees with the grid" are outcomes of
  looking: :class:`~dtscal_lib.detect.Detection` says them with ``found=False`` and a
  :class:`Reason`. A frame a source could not decode is a :class:`~dtscal_lib.sources.frame.Frame`
  whose ``error`` (a :class:`FrameError`) says why; a source never raises for one bad frame.
* **Everything else raises a** :class:`DtscalError`, **and every** ``DtscalError`` **has**
  ``.reason``: the :class:`Reason` under which a pipeline counts it when the error concerns
  one frame or view (``FrameError`` always has one; ``CalibrationError`` and the others when
  they are given one), else ``None``. Code that counts a failure writes
  ``exc.reason or Reason.<default>``: no ``getattr``, no guessing.
"""

from __future__ import annotations

import re
from enum import StrEnum


class Reason(StrEnum):
    """Why a frame (or a detection, or a view) was not used: the keys of every rejection count.

    A ``StrEnum``: each member *is* its string value, so ``Reason.NO_BOARD == "no_board"``,
    ``f"{Reason.NO_BOARD}"`` is ``"no_board"`` and JSON output shows the plain string.

    >>> Reason.NO_BOARD == "no_board", str(Reason.TOO_LARGE), {Reason.EMPTY: 2}
    (True, 'too_large', {'empty': 2})
    """

    # the bytes of a frame (sources)
    EMPTY = "empty"                          #: zero bytes, or an image without pixels
    CORRUPT_JPEG = "corrupt_jpeg"            #: JPEG cut short, stray marker, or undecodable
    CORRUPT_IMAGE = "corrupt_image"          #: another image format that is damaged
    NOT_AN_IMAGE = "not_an_image"            #: bytes (or a file) that are no image format
    UNSUPPORTED_FORMAT = "unsupported_format"  #: an image format the kit does not decode
    TOO_LARGE = "too_large"                  #: declared dimensions beyond the decoding limit
    DECODER_ERROR = "decoder_error"          #: OpenCV's decoder failed on this frame
    NOT_A_FILE = "not_a_file"                #: a FIFO, device or socket where a file was expected
    UNREADABLE = "unreadable"                #: cannot be read from disk, or an invalid message
    TRUNCATED = "truncated"                  #: the recording ends here, cut short
    UNSUPPORTED_ENCODING = "unsupported_encoding"  #: raw sensor_msgs/Image encoding not handled
    VIDEO_DECODE_FAILED = "video_decode_failed"    #: a video stops before its stated end
    # the picture (pipeline and detector)
    SIZE_MISMATCH = "size_mismatch"          #: not the calibration's image size
    BAD_SHAPE = "bad_shape"                  #: array shape that is no image
    BAD_DTYPE = "bad_dtype"                  #: pixel type that is not handled
    BAD_VALUES = "bad_values"                #: NaN or infinite pixels
    DETECTOR_ERROR = "detector_error"        #: OpenCV's detector failed on this frame
    BAD_FRAME = "bad_frame"                  #: any other frame the detector refuses
    NO_BOARD = "no_board"                    #: no board in view
    AT_BORDER = "at_border"                  #: board found, but touching the image border
    INCONSISTENT_GRID = "inconsistent_grid"  #: a corner disagrees with its neighbours' local grid
    # samples and views
    NOT_NEW_COVERAGE = "not_new_coverage"    #: too close to a sample already kept
    OUTLIER_VIEW = "outlier_view"            #: fits far worse than the other views
    BOARD_SIZE = "board_size"                #: the pattern continues past the declared board's corners
    # the extrinsic frame
    BOARD_ORDER = "board_order"              #: corners cannot be ordered on the ground
    CORRUPT_HOMOGRAPHY = "corrupt_homography"  #: fitted H breaks Duckietown's H[1][2] rule
    HORIZON = "horizon"                      #: the image centre lies on the horizon of H
    HOMOGRAPHY_FAILED = "homography_failed"  #: no ground homography fits the corners of this frame

    def __repr__(self) -> str:  # "'no_board'", so dicts of counts in messages read as plain text
        return repr(self.value)

    @classmethod
    def of(cls, value) -> "Reason | str":
        """``value`` as a :class:`Reason` when it names one; other strings pass through unchanged.

        >>> Reason.of("no_board") is Reason.NO_BOARD, Reason.of("my_reason")
        (True, 'my_reason')
        """
        try:
            return cls(value)
        except ValueError:
            return value


class DtscalError(ValueError):
    """Base class: bad input that the user can fix.

    ``reason`` (a :class:`Reason`, or None) says under which key a pipeline counts the error
    when it concerns one frame or view (see the rule at the top of this module).
    """

    reason: "Reason | str | None" = None

    def __init__(self, *args, reason: "Reason | str | None" = None):
        super().__init__(*args)
        self.reason = Reason.of(reason) if reason is not None else None


class CalibrationError(DtscalError):
    """Degenerate or inconsistent calibration input (too few views, NaN, ...).

    ``reason`` (a :class:`Reason`, or None) is set when the error concerns one frame, so a
    pipeline can count it under that reason.
    """

    def __init__(self, message: str = "", reason: "Reason | str | None" = None):
        super().__init__(message, reason=reason)


class CalibrationFileError(DtscalError):
    """A calibration YAML file is missing, malformed, hostile or implausible.

    The message names the file and, where it applies, the field.
    """


class CalibrationFileWarning(UserWarning):
    """A calibration file the kit reads, as Duckietown's own loader does, but with something to say.

    For example a ``projection_matrix`` whose third row is ``[0, 0, 1, 1]`` (Duckietown's
    rectification uses only P's left 3x3), or an extrinsic ``H[1][2] > 0`` (a camera mounted
    upside-down). The message names the file and the field; ``dtscal`` prints it as a warning.
    """


class SourceError(DtscalError):
    """A camera source (bag, video, folder, topic) cannot be opened or read."""


class FrameError(DtscalError):
    """One frame cannot be used (corrupt JPEG, empty, wrong size).

    Pipelines count and skip these; they never stop a stream.
    """

    def __init__(self, reason: "Reason | str", message: str):
        #: short machine-readable reason (a :class:`Reason`), used as a key in rejection counts
        super().__init__(message, reason=reason)


def opencv_message(err: BaseException, limit: int = 200) -> str:
    """The useful part of a ``cv2.error`` (what failed, in which function), on one line.

    >>> opencv_message(Exception("OpenCV(4.12.0) /io/x/resize.cpp:4214: error: (-215:Assertion failed) "
    ...                          "!dsize.empty() in function 'resize'\\n"))
    "(-215:Assertion failed) !dsize.empty() in function 'resize'"
    """
    text = " ".join(str(err).split())
    m = re.search(r"error: (\(.*)", text)
    text = m.group(1) if m else text
    return text if len(text) <= limit else text[: limit - 1] + "…"


class ImplausibleCalibrationError(CalibrationError):
    """A calibration was computed but the kit does not believe it; nothing was written over the robot's file.

    ``doubts`` lists the reasons (each says what to do). ``dtscal`` exits with code 3.
    """

    def __init__(self, message: str, doubts: list[str]):
        super().__init__(message)
        self.doubts = list(doubts)
