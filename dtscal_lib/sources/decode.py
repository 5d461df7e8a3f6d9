"""Turn the bytes of one frame into a BGR image, or say exactly why not.

OpenCV's ``imdecode`` is forgiving in a way that hides broken data: a JPEG cut short
decodes to a picture whose lower part is flat grey, with only a libjpeg warning on
stderr. A calibration fed such a frame would find a board in the top half and never
know. So :func:`decode_image` checks the JPEG end-of-image marker (``FF D9``) *before*
decoding and refuses a JPEG without it.

It is also the one guarded decode path of the kit (bags, folders, the bundled session,
the synthesizer): the declared size is read from the header and checked against
:data:`~.headers.MAX_SIDE` / :data:`~.headers.MAX_PIXELS` before OpenCV allocates anything
(:mod:`.headers`), and every decoder error, ``cv2.error`` included, becomes a
:class:`~dtscal_lib.errors.FrameError` with a :class:`~dtscal_lib.errors.Reason`.
:func:`read_image_file` reads a file for it, refusing FIFOs, devices and files too big to be
a frame.
"""

from __future__ import annotations

import os
import stat

import cv2
import numpy as np

from ..errors import FrameError, Reason, opencv_message
from .headers import JPEG_SOI, MAX_PIXELS, MAX_SIDE, check_dimensions, read_header

JPEG_EOI = b"\xff\xd9"
#: largest image file read from disk (a camera frame at the pixel limit is far smaller)
MAX_FILE_BYTES = 256 * 1024 * 1024


def _strip_padding(data: bytes) -> bytes:
    # some encoders pad a JPEG after its end marker (zeros, a newline); ignore that tail
    return data.rstrip(b"\x00\r\n ")


#: markers that may legally follow 0xFF inside the scan data of a baseline JPEG: byte stuffing
#: (00), restart markers (D0-D7), fill bytes (FF), and the table/scan markers of a
#: multi-scan file (C4 DHT, DA SOS, DB DQT, DD DRI)
_SCAN_OK = np.zeros(256, dtype=bool)
_SCAN_OK[[0x00, 0xFF, 0xC4, 0xDA, 0xDB, 0xDD]] = True
_SCAN_OK[0xD0:0xD8] = True


def jpeg_scan_problem(raw: bytes) -> str | None:
    """Look for a stray marker inside the entropy-coded data of a JPEG.

    libjpeg meets such a marker as "Corrupt JPEG data: premature end of data segment",
    prints a warning and fills the rest of the picture with grey. A damaged transfer
    produces exactly that. Returns a description of the first problem, or None.
    Only the marker structure is checked (cheap, vectorized); a flipped bit that keeps the
    structure intact is not found.
    """
    arr = np.frombuffer(raw, dtype=np.uint8)
    n = arr.size
    pos = 2
    # walk the marker segments up to the first start-of-scan
    while True:
        if pos + 4 > n or arr[pos] != 0xFF:
            return f"broken marker structure at byte {pos}"
        marker = int(arr[pos + 1])
        if marker == 0xFF:  # fill byte
            pos += 1
            continue
        if marker in (0xC2, 0xC6, 0xCA, 0xCE):  # progressive: scans interleave with tables, skip the check
            return None
        seglen = (int(arr[pos + 2]) << 8) | int(arr[pos + 3])
        if seglen < 2:
            return f"segment of length {seglen} at byte {pos}"
        pos += 2 + seglen
        if marker == 0xDA:
            break
    end = len(_strip_padding(raw)) - 2  # the final FF D9
    if pos >= end:
        return "no scan data"
    ff = np.flatnonzero(arr[pos:end] == 0xFF) + pos
    following = arr[np.minimum(ff + 1, n - 1)]
    bad = ff[~_SCAN_OK[following]]
    if bad.size:
        return f"stray marker FF {int(arr[bad[0] + 1]):02X} inside the image data at byte {int(bad[0])}"
    return None


def read_image_file(path: str | os.PathLike, name: str | None = None) -> bytes:
    """The bytes of an image file, refusing what cannot be a frame file.

    The file is opened without blocking and checked with ``fstat`` on the open descriptor,
    so a FIFO (which would block forever), a device such as ``/dev/zero`` (endless), a
    socket, or a symlink to one is refused, and so is a regular file larger than
    :data:`MAX_FILE_BYTES`.

    Raises
    ------
    FrameError
        ``not_a_file`` for a FIFO, device or socket; ``too_large`` beyond the size limit;
        ``unreadable`` when the file cannot be opened or read.
    """
    name = name or os.fspath(path)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0))
    except OSError as err:
        raise FrameError(Reason.UNREADABLE, f"cannot read {name}: {err.strerror}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise FrameError(Reason.NOT_A_FILE, f"{name} is {describe_file_type(st.st_mode)}, not a regular file; "
                                                "it is skipped (copy the frames into a folder as files)")
        if st.st_size > MAX_FILE_BYTES:
            raise FrameError(Reason.TOO_LARGE, f"{name} has {st.st_size} bytes, more than the {MAX_FILE_BYTES >> 20} "
                                               "MiB an image frame may have; it is skipped")
        with os.fdopen(fd, "rb", closefd=False) as f:
            data = f.read(MAX_FILE_BYTES + 1)
    except OSError as err:
        raise FrameError(Reason.UNREADABLE, f"cannot read {name}: {err.strerror}") from None
    finally:
        os.close(fd)
    if len(data) > MAX_FILE_BYTES:
        raise FrameError(Reason.TOO_LARGE, f"{name} grew beyond {MAX_FILE_BYTES >> 20} MiB while being read; skipped")
    return data


def describe_file_type(mode: int) -> str:
    """``"a FIFO (named pipe)"``, ``"a character device"``, ... for a non-regular ``st_mode``."""
    for test, text in ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"), (stat.S_ISDIR, "a folder")):
        if test(mode):
            return text
    return "not a regular file"


def is_jpeg(data: bytes) -> bool:
    """True when ``data`` starts with the JPEG start-of-image marker."""
    return data[:3] == JPEG_SOI


def decode_image(data: bytes | bytearray | memoryview | np.ndarray) -> np.ndarray:
    """Decode an encoded still image (JPEG, PNG, BMP, TIFF, ...) to BGR.

    Parameters
    ----------
    data : bytes-like or (N,) uint8 array
        The encoded file content, e.g. ``CompressedImage.data`` from a ROS bag.

    Returns
    -------
    (H, W, 3) uint8 array, BGR channel order (grey images are expanded to three channels).

    Raises
    ------
    FrameError
        ``reason="empty"`` for zero bytes; ``"corrupt_jpeg"`` for a JPEG that lacks its
        end-of-image marker (cut short), has a stray marker inside its image data (see
        :func:`jpeg_scan_problem`) or that OpenCV cannot decode; ``"corrupt_image"``
        for another format that does not decode or whose header is damaged;
        ``"too_large"`` when the header declares more than ``MAX_SIDE`` px a side or
        ``MAX_PIXELS`` pixels (checked before decoding); ``"decoder_error"`` when OpenCV
        raises; ``"unsupported_format"`` for GIF, JPEG 2000, EXR, HDR, ...;
        ``"not_an_image"`` for bytes that are no image format at all.

    Examples
    --------
    >>> ok, buf = cv2.imencode(".jpg", np.zeros((4, 6, 3), np.uint8))
    >>> decode_image(buf.tobytes()).shape
    (4, 6, 3)
    """
    if isinstance(data, np.ndarray):
        raw = np.ascontiguousarray(data, dtype=np.uint8).reshape(-1).tobytes()
    else:
        raw = bytes(data)
    if len(raw) == 0:
        raise FrameError(Reason.EMPTY, "the frame holds no data (0 bytes); the camera sent an empty message")
    jpeg = is_jpeg(raw)
    if jpeg and not _strip_padding(raw).endswith(JPEG_EOI):
        raise FrameError(
            Reason.CORRUPT_JPEG,
            f"JPEG of {len(raw)} bytes has no end-of-image marker (FF D9): it was cut short "
            "in transfer or recording; the frame is skipped",
        )
    header = read_header(raw)
    check_dimensions(header.width, header.height, f"{header.format} of {len(raw)} bytes")
    if jpeg:
        problem = jpeg_scan_problem(raw)
        if problem is not None:
            raise FrameError(Reason.CORRUPT_JPEG,
                             f"JPEG of {len(raw)} bytes is damaged ({problem}); the frame is skipped")
    buf = np.frombuffer(raw, dtype=np.uint8)
    level = cv2.getLogLevel()
    cv2.setLogLevel(0)  # silent: OpenCV would print its own copy of a decoder error on stderr
    try:
        image = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    except cv2.error as err:
        detail = opencv_message(err)
        raise FrameError(Reason.DECODER_ERROR, f"OpenCV's decoder failed on a {header.format} of {len(raw)} bytes "
                                               f"({detail}); the frame is skipped") from None
    finally:
        cv2.setLogLevel(level)
    if image is None or image.size == 0:
        reason = Reason.CORRUPT_JPEG if jpeg else Reason.CORRUPT_IMAGE
        raise FrameError(reason, f"{header.format} of {len(raw)} bytes is damaged and cannot be decoded; "
                                 "the frame is skipped")
    if image.shape[0] * image.shape[1] > MAX_PIXELS or max(image.shape[:2]) > MAX_SIDE:  # never, if headers agree
        raise FrameError(Reason.TOO_LARGE, f"{header.format} decoded to {image.shape[1]}x{image.shape[0]} pixels, "
                                           "beyond the kit's limit; the frame is skipped")
    if image.ndim == 2:
        image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    return image


#: raw sensor_msgs/Image encodings that :func:`raw_image_to_bgr` converts
RAW_ENCODINGS = ("bgr8", "rgb8", "mono8", "bgra8", "rgba8", "8UC1", "8UC3")


def raw_image_to_bgr(height: int, width: int, encoding: str, step: int, data: bytes | np.ndarray) -> np.ndarray:
    """Convert the pixel buffer of a raw ``sensor_msgs/Image`` to BGR.

    Parameters
    ----------
    height, width : image size in pixels
    encoding : one of :data:`RAW_ENCODINGS`
    step : bytes per row (may exceed ``width * channels`` for padded rows)
    data : (step * height,) bytes

    Returns
    -------
    (height, width, 3) uint8 BGR array (a copy).

    Raises
    ------
    FrameError
        ``"empty"`` for a zero-size image, ``"unsupported_encoding"`` for other encodings,
        ``"truncated"`` when ``data`` is shorter than ``step * height``.
    """
    channels = {"bgr8": 3, "rgb8": 3, "8UC3": 3, "mono8": 1, "8UC1": 1, "bgra8": 4, "rgba8": 4}.get(encoding)
    if channels is None:
        raise FrameError(
            Reason.UNSUPPORTED_ENCODING,
            f"raw image encoding {encoding!r} is not supported; record the camera's compressed topic "
            f"(image/compressed) or use one of {', '.join(RAW_ENCODINGS)}",
        )
    height, width, step = int(height), int(width), int(step)
    if height <= 0 or width <= 0:
        raise FrameError(Reason.EMPTY, f"raw image has size {width}x{height}")
    check_dimensions(width, height, f"raw {encoding} image")
    if step < width * channels:
        raise FrameError(Reason.CORRUPT_IMAGE,
                         f"raw image row step {step} is smaller than width*channels = {width * channels}")
    buf = np.frombuffer(bytes(data) if not isinstance(data, np.ndarray) else data.astype(np.uint8).tobytes(), np.uint8)
    if buf.size < step * height:
        raise FrameError(Reason.TRUNCATED, f"raw image has {buf.size} bytes, expected step*height = {step * height}")
    rows = buf[: step * height].reshape(height, step)[:, : width * channels]
    img = rows.reshape(height, width, channels)
    if encoding in ("mono8", "8UC1"):
        return cv2.cvtColor(img[:, :, 0], cv2.COLOR_GRAY2BGR)
    if encoding == "rgb8":
        return cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
    if encoding == "bgra8":
        return cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    if encoding == "rgba8":
        return cv2.cvtColor(img, cv2.COLOR_RGBA2BGR)
    return img.copy()


__all__ = ["decode_image", "read_image_file", "describe_file_type", "jpeg_scan_problem", "raw_image_to_bgr", "is_jpeg",
           "RAW_ENCODINGS", "MAX_FILE_BYTES"]
