"""Read the declared size of an encoded image from its header, without decoding it.

A decoder allocates what the header declares. A 47 KB JPEG whose frame header claims
30000 x 30000 pixels makes OpenCV reserve gigabytes before it finds that the data is
garbage, and beyond ``CV_IO_MAX_IMAGE_PIXELS`` it raises. So :func:`read_header` parses the
few header bytes of every format the kit decodes (JPEG, PNG, BMP, PNM/PAM, TIFF, WebP) and
:func:`check_dimensions` refuses a size beyond :data:`MAX_SIDE` / :data:`MAX_PIXELS` before
any pixel is decoded. Only formats whose header this module reads are ever handed to
OpenCV; other formats OpenCV knows (GIF, JPEG 2000, OpenEXR, Radiance HDR, Sun raster,
PFM, AVIF) are refused as ``unsupported_format``.

Every refusal is a :class:`~dtscal_lib.errors.FrameError` with a :class:`~dtscal_lib.errors.Reason`.

>>> read_header(b"P5 640 480 255\\n" + bytes(640 * 480))
ImageHeader(format='PGM', width=640, height=480)
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from ..errors import FrameError, Reason

#: largest width or height decoded, in pixels
MAX_SIDE = 8192
#: largest number of pixels decoded (50 Mpx: 150 MB as BGR; OpenCV's own limit is 1 Gpx)
MAX_PIXELS = 50_000_000

#: formats :func:`read_header` reads, for messages
SUPPORTED = "JPEG, PNG, BMP, PPM/PGM/PBM/PAM, TIFF, WebP"

JPEG_SOI = b"\xff\xd8\xff"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"

#: formats OpenCV may decode that the kit refuses (no header check written for them)
_REFUSED = (
    (b"GIF87a", "GIF"), (b"GIF89a", "GIF"), (b"\x00\x00\x00\x0cjP  ", "JPEG 2000"), (b"\xff\x4f\xff\x51", "JPEG 2000"),
    (b"\x76\x2f\x31\x01", "OpenEXR"), (b"#?RADIANCE", "Radiance HDR"), (b"#?RGBE", "Radiance HDR"),
    (b"\x59\xa6\x6a\x95", "Sun raster"), (b"PF\n", "PFM"), (b"Pf\n", "PFM"), (b"PF\r", "PFM"), (b"Pf\r", "PFM"),
)


@dataclass(frozen=True)
class ImageHeader:
    """What an image file declares: its format name and its size in pixels."""

    format: str
    width: int
    height: int


def _corrupt(fmt: str, what: str) -> FrameError:
    reason = Reason.CORRUPT_JPEG if fmt == "JPEG" else Reason.CORRUPT_IMAGE
    return FrameError(reason, f"{fmt} header is damaged ({what}); the frame is skipped")


def _jpeg(raw: bytes) -> ImageHeader:
    pos, n = 2, len(raw)
    while True:
        if pos + 2 > n:
            raise _corrupt("JPEG", "the file ends before the frame header (SOF)")
        if raw[pos] != 0xFF:
            raise _corrupt("JPEG", f"broken marker structure at byte {pos}")
        marker = raw[pos + 1]
        if marker == 0xFF:  # fill byte
            pos += 1
            continue
        if marker == 0x01 or 0xD0 <= marker <= 0xD7:  # markers without a length
            pos += 2
            continue
        if marker in (0xD9, 0xDA):
            raise _corrupt("JPEG", "no frame header (SOF) before the image data")
        if pos + 4 > n:
            raise _corrupt("JPEG", "the file ends inside a marker segment")
        seglen = (raw[pos + 2] << 8) | raw[pos + 3]
        if seglen < 2:
            raise _corrupt("JPEG", f"segment of length {seglen} at byte {pos}")
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            if seglen < 8 or pos + 9 > n:
                raise _corrupt("JPEG", "frame header (SOF) cut short")
            height = (raw[pos + 5] << 8) | raw[pos + 6]
            width = (raw[pos + 7] << 8) | raw[pos + 8]
            return ImageHeader("JPEG", width, height)
        pos += 2 + seglen


def _png(raw: bytes) -> ImageHeader:
    if len(raw) < 24 or raw[12:16] != b"IHDR":
        raise _corrupt("PNG", "the first chunk is not IHDR")
    width, height = struct.unpack(">II", raw[16:24])
    return ImageHeader("PNG", width, height)


def _bmp(raw: bytes) -> ImageHeader:
    if len(raw) < 18:
        raise _corrupt("BMP", "the file ends inside the header")
    (dib,) = struct.unpack_from("<I", raw, 14)
    if dib == 12:
        if len(raw) < 22:
            raise _corrupt("BMP", "the file ends inside the header")
        width, height = struct.unpack_from("<HH", raw, 18)
    elif 40 <= dib <= 1024:
        if len(raw) < 26:
            raise _corrupt("BMP", "the file ends inside the header")
        width, height = struct.unpack_from("<ii", raw, 18)
        if width < 0:
            raise _corrupt("BMP", f"negative width {width}")
        height = abs(height)  # negative height: rows stored top-down
    else:
        raise _corrupt("BMP", f"unknown info header size {dib}")
    return ImageHeader("BMP", width, height)


def _pnm_tokens(raw: bytes, start: int, count: int) -> list[bytes]:
    """The next ``count`` whitespace-separated tokens of a PNM header (``#`` comments skipped)."""
    tokens: list[bytes] = []
    pos, n = start, min(len(raw), 4096)  # a real PNM header is a few dozen bytes
    while len(tokens) < count:
        while pos < n and raw[pos] in b" \t\r\n\v\f":
            pos += 1
        if pos < n and raw[pos] == ord("#"):
            while pos < n and raw[pos] not in b"\r\n":
                pos += 1
            continue
        end = pos
        while end < n and raw[end] not in b" \t\r\n\v\f#":
            end += 1
        if end == pos:
            break
        tokens.append(raw[pos:end])
        pos = end
    return tokens


def _pnm_int(token: bytes, fmt: str, field: str) -> int:
    if not token.isdigit():
        raise _corrupt(fmt, f"{field} is {token[:20]!r}, not a number")
    if len(token) > 9:  # beyond any limit; never convert a 5000-digit string
        raise FrameError(Reason.TOO_LARGE, f"{fmt} declares a {field} of {len(token)} digits; the frame is skipped")
    return int(token)


def _pnm(raw: bytes) -> ImageHeader:
    kind = raw[1:2]
    fmt = {b"1": "PBM", b"4": "PBM", b"2": "PGM", b"5": "PGM", b"3": "PPM", b"6": "PPM", b"7": "PAM"}[kind]
    if fmt == "PAM":
        fields: dict[bytes, bytes] = {}
        for line in raw[3:4096].splitlines():
            parts = line.split()
            if not parts or parts[0].startswith(b"#"):
                continue
            if parts[0] == b"ENDHDR":
                break
            if len(parts) >= 2:
                fields[parts[0]] = parts[1]
        if b"WIDTH" not in fields or b"HEIGHT" not in fields:
            raise _corrupt(fmt, "no WIDTH or HEIGHT line")
        return ImageHeader(fmt, _pnm_int(fields[b"WIDTH"], fmt, "width"), _pnm_int(fields[b"HEIGHT"], fmt, "height"))
    tokens = _pnm_tokens(raw, 2, 2)
    if len(tokens) < 2:
        raise _corrupt(fmt, "the header ends before width and height")
    return ImageHeader(fmt, _pnm_int(tokens[0], fmt, "width"), _pnm_int(tokens[1], fmt, "height"))


def _tiff(raw: bytes) -> ImageHeader:
    endian = "<" if raw[:2] == b"II" else ">"
    (version,) = struct.unpack_from(endian + "H", raw, 2)
    big = version == 43
    try:
        if big:
            (ifd,) = struct.unpack_from(endian + "Q", raw, 8)
            (count,) = struct.unpack_from(endian + "Q", raw, ifd)
            first, size = ifd + 8, 20
        else:
            (ifd,) = struct.unpack_from(endian + "I", raw, 4)
            (count,) = struct.unpack_from(endian + "H", raw, ifd)
            first, size = ifd + 2, 12
    except struct.error:
        raise _corrupt("TIFF", "the first directory (IFD) lies outside the file") from None
    tags: dict[int, int] = {}
    for i in range(min(count, 4096)):
        at = first + i * size
        try:
            tag, typ = struct.unpack_from(endian + "HH", raw, at)
            value_at = at + (12 if big else 8)
            if typ == 3:  # SHORT
                (value,) = struct.unpack_from(endian + "H", raw, value_at)
            elif typ == 4:  # LONG
                (value,) = struct.unpack_from(endian + "I", raw, value_at)
            elif typ == 16 and big:  # LONG8
                (value,) = struct.unpack_from(endian + "Q", raw, value_at)
            else:
                continue
        except struct.error:
            raise _corrupt("TIFF", "the first directory (IFD) is cut short") from None
        if tag in (256, 257, 322, 323):
            tags.setdefault(tag, value)
    if 256 not in tags or 257 not in tags:
        raise _corrupt("TIFF", "no ImageWidth / ImageLength tag in the first directory")
    header = ImageHeader("TIFF", tags[256], tags[257])
    for tag, name in ((322, "tile width"), (323, "tile length")):
        if tags.get(tag, 0) > MAX_SIDE:
            raise FrameError(Reason.TOO_LARGE, f"TIFF declares a {name} of {tags[tag]} px, beyond the limit of "
                                               f"{MAX_SIDE} px; the frame is skipped")
    return header


def _webp(raw: bytes) -> ImageHeader:
    chunk = raw[12:16]
    if chunk == b"VP8 " and len(raw) >= 30:
        if raw[23:26] != b"\x9d\x01\x2a":
            raise _corrupt("WebP", "no VP8 start code")
        width, height = struct.unpack_from("<HH", raw, 26)
        return ImageHeader("WebP", width & 0x3FFF, height & 0x3FFF)
    if chunk == b"VP8L" and len(raw) >= 25:
        if raw[20] != 0x2F:
            raise _corrupt("WebP", "no VP8L signature")
        (bits,) = struct.unpack_from("<I", raw, 21)
        return ImageHeader("WebP", (bits & 0x3FFF) + 1, ((bits >> 14) & 0x3FFF) + 1)
    if chunk == b"VP8X" and len(raw) >= 30:
        width = int.from_bytes(raw[24:27], "little") + 1
        height = int.from_bytes(raw[27:30], "little") + 1
        return ImageHeader("WebP", width, height)
    raise _corrupt("WebP", f"unknown or cut-short chunk {chunk!r}")


def read_header(raw: bytes) -> ImageHeader:
    """Format and declared size of an encoded image.

    Raises
    ------
    FrameError
        ``corrupt_jpeg`` / ``corrupt_image`` for a damaged header, ``unsupported_format`` for
        a format the kit does not decode, ``not_an_image`` for other bytes, ``too_large`` for a
        PNM size with absurdly many digits.
    """
    if raw.startswith(JPEG_SOI):
        return _jpeg(raw)
    if raw.startswith(PNG_MAGIC):
        return _png(raw)
    if raw.startswith(b"BM"):
        return _bmp(raw)
    if len(raw) >= 3 and raw[:1] == b"P" and raw[1:2] in b"1234567" and raw[2:3] in b" \t\r\n#":
        return _pnm(raw)
    if raw[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
        return _tiff(raw)
    if raw[:4] == b"RIFF" and raw[8:12] == b"WEBP":
        return _webp(raw)
    for magic, name in _REFUSED:
        if raw.startswith(magic):
            raise FrameError(Reason.UNSUPPORTED_FORMAT, f"{name} images are not read by the kit; convert the "
                                                        f"frames to PNG or JPEG (read: {SUPPORTED})")
    if raw[4:8] == b"ftyp":
        raise FrameError(Reason.UNSUPPORTED_FORMAT, f"HEIF/AVIF images are not read by the kit; convert the "
                                                    f"frames to PNG or JPEG (read: {SUPPORTED})")
    raise FrameError(Reason.NOT_AN_IMAGE, f"{len(raw)} bytes starting {raw[:8]!r} are not an image format the kit "
                                          f"reads ({SUPPORTED})")


def check_dimensions(width: int, height: int, what: str = "the image") -> None:
    """Refuse a size that is empty or beyond :data:`MAX_SIDE` / :data:`MAX_PIXELS`.

    >>> check_dimensions(40000, 40000, "JPEG")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    dtscal_lib.errors.FrameError: JPEG declares 40000x40000 pixels, beyond the kit's limit ...
    """
    if width <= 0 or height <= 0:
        raise FrameError(Reason.CORRUPT_IMAGE, f"{what} declares {width}x{height} pixels (an empty picture); "
                                               "the frame is skipped")
    if width > MAX_SIDE or height > MAX_SIDE or width * height > MAX_PIXELS:
        raise FrameError(
            Reason.TOO_LARGE,
            f"{what} declares {width}x{height} pixels, beyond the kit's limit of {MAX_SIDE} px a side and "
            f"{MAX_PIXELS // 1_000_000} Mpx; the frame is skipped (a damaged or hostile header, or a picture far "
            "larger than a camera frame: scale it down)",
        )


__all__ = ["ImageHeader", "read_header", "check_dimensions", "MAX_SIDE", "MAX_PIXELS", "SUPPORTED"]
