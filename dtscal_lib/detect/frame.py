"""The result of looking for a board (:class:`Detection`), any frame as 8-bit gray, and drawing."""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from ..boards import DUCKIETOWN_BOARD, Board
from ..errors import FrameError, Reason

REASON_NO_BOARD = Reason.NO_BOARD
REASON_AT_BORDER = Reason.AT_BORDER
REASON_INCONSISTENT = Reason.INCONSISTENT_GRID


@dataclass(frozen=True)
class Detection:
    """The result of looking for a board in one frame.

    Attributes
    ----------
    found : bool
        True when the whole board was detected and no corner is near the image border.
    corners : (N, 2) float64 sub-pixel pixels or None
        Inner corners in the board's row-major order (``board.cols`` per row), rows
        running top to bottom. Also set when ``reason == "at_border"`` (so a UI can
        show the rejected board); ``None`` when no board was found.
    reason : str or None
        ``None`` when found, else ``"no_board"``, ``"at_border"`` or ``"inconsistent_grid"``
        (a board was found but some corner disagrees with its neighbours' grid even after
        re-refinement: rejected as unreliable rather than fed to a calibration; ``corners``
        holds the rejected board and ``detail`` names the corner and its distance).
    board : Board
    image_size : (w, h)
    detail : str or None
        For a found-and-rejected board (``"inconsistent_grid"``): which corner (row and column
        of the board's inner-corner grid, from 1) is how far off its neighbours' grid, against
        which tolerance.
    pattern_seen : (cols, rows) or None
        The live detector's saddle walk found a bigger grid of equally strong corners than the declared
        board: the size to pass (``--board CxR``), else None.
    """

    found: bool
    corners: np.ndarray | None
    reason: str | None
    board: Board = field(default=DUCKIETOWN_BOARD)
    image_size: tuple[int, int] = (0, 0)
    detail: str | None = None
    #: ``(cols, rows)`` of inner corners when the saddles show the pattern continuing past the declared board's
    #: corners (a bigger board declared too small: a sub-grid was found), else None
    pattern_seen: tuple[int, int] | None = None
    #: a ChArUco board's view: the id of each corner (:class:`~dtscal_lib.boards.CharucoBoard`'s numbering,
    #: ``corners`` then holds only the corners seen, in this order); None for a chessboard (all corners)
    ids: np.ndarray | None = None

    def __bool__(self) -> bool:
        return self.found


# --------------------------------------------------------------------------- input
def to_gray(image) -> np.ndarray:
    """Any camera frame as a contiguous 8-bit gray image.

    Parameters
    ----------
    image : (h, w), (h, w, 1), (h, w, 3) BGR or (h, w, 4) BGRA array
        ``uint8``; ``uint16`` (scaled by 1/257); ``bool``; or float (values in [0, 1]
        are scaled by 255, larger values are taken as 0-255 and clipped).

    Returns
    -------
    (h, w) uint8

    Raises
    ------
    FrameError
        ``reason="empty"`` for ``None`` or an empty array, ``"bad_shape"`` for other shapes,
        ``"bad_dtype"`` for unsupported pixel types, ``"bad_values"`` for NaN/inf pixels.
    """
    if image is None:
        raise FrameError(Reason.EMPTY, "the frame is None; the source returned no image (check the camera/bag)")
    img = np.asarray(image)
    if img.size == 0:
        raise FrameError(Reason.EMPTY, f"the frame is empty (shape {img.shape}); skip it and read the next one")
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if not (img.ndim == 2 or (img.ndim == 3 and img.shape[2] in (3, 4))):
        raise FrameError(
            Reason.BAD_SHAPE,
            f"expected a gray (h, w), BGR (h, w, 3) or BGRA (h, w, 4) image, got shape {img.shape}; "
            "decode the frame to an image first",
        )
    img = _to_uint8(img)
    if img.ndim == 3:
        code = cv2.COLOR_BGR2GRAY if img.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
        img = cv2.cvtColor(np.ascontiguousarray(img), code)
    return np.ascontiguousarray(img)


def _to_uint8(img: np.ndarray) -> np.ndarray:
    if img.dtype == np.uint8:
        return img
    if img.dtype == np.bool_:
        return img.astype(np.uint8) * 255
    if img.dtype == np.uint16:
        return ((img.astype(np.uint32) + 128) // 257).astype(np.uint8)
    if np.issubdtype(img.dtype, np.floating):
        if not np.all(np.isfinite(img)):
            raise FrameError(Reason.BAD_VALUES, "the frame contains NaN or infinite pixels; it cannot be used")
        scale = 255.0 if float(img.max()) <= 1.0 else 1.0
        return np.clip(np.rint(img * scale), 0, 255).astype(np.uint8)
    raise FrameError(
        Reason.BAD_DTYPE,
        f"unsupported pixel type {img.dtype}; give uint8, uint16 or float images (e.g. img.astype(np.uint8))",
    )


def _as_bgr(image) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim == 2:
        return cv2.cvtColor(_to_uint8(img), cv2.COLOR_GRAY2BGR)
    if img.ndim == 3 and img.shape[2] == 4:
        return cv2.cvtColor(_to_uint8(img), cv2.COLOR_BGRA2BGR)
    if img.ndim == 3 and img.shape[2] == 3:
        return _to_uint8(img).copy()
    raise FrameError(Reason.BAD_SHAPE, f"cannot draw on an image of shape {img.shape}")


def draw_detection(image, detection: Detection) -> np.ndarray:
    """A BGR copy of ``image`` with the detection drawn like ``cv2.drawChessboardCorners``.

    A found board gets coloured corners joined row by row; a board rejected at the border
    gets red circles; nothing is drawn when no board was found.

    Parameters
    ----------
    image : gray, BGR or BGRA frame
    detection : Detection for this image

    Returns
    -------
    (h, w, 3) uint8 BGR
    """
    out = _as_bgr(image)
    if detection.corners is not None and detection.ids is not None:  # a partial ChArUco view: its corners, ids
        pts = np.asarray(detection.corners, dtype=np.float32).reshape(-1, 1, 2)
        cv2.aruco.drawDetectedCornersCharuco(out, pts, np.asarray(detection.ids, np.int32).reshape(-1, 1))
    elif detection.corners is not None:
        pts = np.asarray(detection.corners, dtype=np.float32).reshape(-1, 1, 2)
        cv2.drawChessboardCorners(out, detection.board.pattern_size, pts, bool(detection.found))
    return out
