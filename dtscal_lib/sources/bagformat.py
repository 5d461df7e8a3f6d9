"""A small, tolerant, sequential reader of ROS 1 bag files (format v2.0).

``rosbags`` (the normal reader) needs the bag's index, which ROS writes at the *end* of
the file when a recording is closed. A bag cut short (a copy that stopped, a full SD
card) or a recording that was killed has no usable index, and ``rosbags`` refuses it.
Everything before the cut is still there, record after record; this module walks the
file from the start and hands out every message it can read, then says how the walk
ended.

The format (http://wiki.ros.org/Bags/Format/2.0), all integers little-endian::

    file    = "#ROSBAG V2.0\\n" record*
    record  = header_len:uint32 header data_len:uint32 data
    header  = (field_len:uint32 "name=" value)*       one field is op:uint8

    op 0x03 bag header   index_pos:uint64 conn_count:uint32 chunk_count:uint32 (data: padding)
    op 0x05 chunk        compression:"none"|"bz2"|"lz4" size:uint32 (data: records 0x07 and 0x02)
    op 0x07 connection   conn:uint32 topic (data: a header with topic, type, md5sum,
                         message_definition, callerid, latching)
    op 0x02 message data conn:uint32 time:(sec:uint32, nsec:uint32) (data: serialized message)
    op 0x04 index data, 0x06 chunk info: the index; skipped here.

A chunk cut in the middle still gives up the records it holds before the cut: an
uncompressed chunk directly, bz2 and lz4 chunks through a streaming decompressor. The
decompressor never produces more than the chunk's declared size, and no chunk or record
beyond :data:`MAX_CHUNK_BYTES` is read: a decompression bomb ends the walk with status
``"too_large"``.

This is the only reader of message data in the kit (the bundled session included);
``rosbags`` is used for the index only, because it decompresses a whole chunk without bound.
"""

from __future__ import annotations

import bz2
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

MAGIC = b"#ROSBAG V2.0\n"
OP_MSG_DATA = 0x02
OP_BAG_HEADER = 0x03
OP_INDEX_DATA = 0x04
OP_CHUNK = 0x05
OP_CHUNK_INFO = 0x06
OP_CONNECTION = 0x07

#: a record header larger than this is garbage, not a header (real ones are < 200 bytes;
#: a connection's long message definition lives in its data, not its header)
_MAX_HEADER = 1 << 20
#: largest chunk (uncompressed) or record read: ROS writes 768 KiB chunks, and a single
#: message bigger than that (a raw 4K frame is 25 MB) gets a chunk of its own
MAX_CHUNK_BYTES = 128 * 1024 * 1024

_u32 = struct.Struct("<I")
_u64 = struct.Struct("<Q")


@dataclass(frozen=True)
class RawConnection:
    """A connection record: which topic and message type ``conn`` ids refer to."""

    conn_id: int
    topic: str
    msgtype: str  # as written in the bag, e.g. "sensor_msgs/CompressedImage"
    md5sum: str
    msgdef: str


@dataclass(frozen=True)
class RawMessage:
    """A message record: serialized bytes of one message on connection ``conn_id``."""

    conn_id: int
    time_ns: int
    data: bytes


@dataclass(frozen=True)
class ScanEnd:
    """How a sequential walk through a bag ended.

    status
        ``"complete"``: the whole file was read, index included.
        ``"no_index"``: the file ends cleanly between records but without the index that a
        closed recording has (recording killed, or the copy cut exactly between records).
        ``"truncated"``: the file ends in the middle of a record.
        ``"damaged"``: a record is malformed (garbage where a header should be).
        ``"too_large"``: a chunk or record declares (or decompresses to) more than
        :data:`MAX_CHUNK_BYTES`; the walk stops there instead of allocating it.
    offset
        Byte offset of the record where the walk stopped (file size when complete).
    detail
        One sentence for humans.
    """

    status: str
    offset: int
    detail: str


class _Cut(Exception):
    """The data ends inside a record."""


class _Garbage(Exception):
    """The bytes at this point are not a record."""


def parse_fields(header: bytes) -> dict[str, bytes]:
    """Split a record header into ``{name: raw value}``.

    Raises ``_Garbage`` when the field lengths do not add up or a field has no ``=``.
    """
    fields: dict[str, bytes] = {}
    pos, n = 0, len(header)
    while pos < n:
        if pos + 4 > n:
            raise _Garbage("field length runs past the header")
        (flen,) = _u32.unpack_from(header, pos)
        pos += 4
        if flen > n - pos:
            raise _Garbage("field runs past the header")
        field = header[pos : pos + flen]
        pos += flen
        eq = field.find(b"=")
        if eq <= 0:
            raise _Garbage("header field without a name")
        fields[field[:eq].decode("latin-1")] = field[eq + 1 :]
    return fields


def _op(fields: dict[str, bytes]) -> int:
    op = fields.get("op")
    if op is None or len(op) != 1:
        raise _Garbage("record header has no op code")
    return op[0]


def _uint(fields: dict[str, bytes], name: str) -> int:
    raw = fields.get(name)
    if raw is None:
        raise _Garbage(f"record has no {name!r} field")
    if len(raw) == 4:
        return _u32.unpack(raw)[0]
    if len(raw) == 8:
        return _u64.unpack(raw)[0]
    if len(raw) == 1:
        return raw[0]
    raise _Garbage(f"field {name!r} has {len(raw)} bytes")


def _time_ns(fields: dict[str, bytes]) -> int:
    raw = fields.get("time")
    if raw is None or len(raw) != 8:
        raise _Garbage("message record has no 8-byte time field")
    sec, nsec = struct.unpack("<II", raw)
    return sec * 1_000_000_000 + nsec


def _connection(fields: dict[str, bytes], data: bytes) -> RawConnection:
    conn_id = _uint(fields, "conn")
    topic = fields.get("topic", b"").decode("utf-8", "replace")
    info = parse_fields(data)
    return RawConnection(
        conn_id=conn_id,
        topic=topic or info.get("topic", b"").decode("utf-8", "replace"),
        msgtype=info.get("type", b"").decode("utf-8", "replace"),
        md5sum=info.get("md5sum", b"").decode("ascii", "replace"),
        msgdef=info.get("message_definition", b"").decode("utf-8", "replace"),
    )


def _records_in(buf: bytes) -> Iterator[tuple[dict[str, bytes], bytes]]:
    """Records packed in a byte buffer (the inside of a chunk); ``_Cut`` at a partial one."""
    pos, n = 0, len(buf)
    while pos < n:
        if pos + 4 > n:
            raise _Cut()
        (hlen,) = _u32.unpack_from(buf, pos)
        if hlen > _MAX_HEADER:
            raise _Garbage(f"header length {hlen} inside a chunk")
        if pos + 4 + hlen + 4 > n:
            raise _Cut()
        fields = parse_fields(buf[pos + 4 : pos + 4 + hlen])
        (dlen,) = _u32.unpack_from(buf, pos + 4 + hlen)
        start = pos + 8 + hlen
        if start + dlen > n:
            raise _Cut()
        yield fields, buf[start : start + dlen]
        pos = start + dlen


class _TooLarge(Exception):
    """A chunk or record beyond :data:`MAX_CHUNK_BYTES`."""


def _decompress(compression: str, data: bytes, complete: bool, size: int | None = None) -> tuple[bytes, bool]:
    """Chunk payload -> (raw records, whether the payload was complete).

    A partial payload is decompressed as far as it goes. ``size`` is the chunk's declared
    uncompressed size: the output is never allowed beyond it (nor beyond
    :data:`MAX_CHUNK_BYTES`), so a few kilobytes of bz2 cannot expand into gigabytes.
    """
    limit = MAX_CHUNK_BYTES if size is None else size
    if limit > MAX_CHUNK_BYTES:
        raise _TooLarge(f"chunk declares {limit} bytes uncompressed, beyond the limit of {MAX_CHUNK_BYTES >> 20} MiB")
    if compression == "none":
        return data, complete
    if compression == "bz2":
        dec = bz2.BZ2Decompressor()
        try:
            out = dec.decompress(data, max_length=limit + 1)
        except (OSError, ValueError, EOFError) as err:
            raise _Garbage(f"bz2 chunk does not decompress: {err}") from None
    elif compression == "lz4":
        try:
            import lz4.frame  # rosbags depends on it
        except ImportError:  # pragma: no cover - rosbags always brings lz4
            raise _Garbage("lz4 chunk but the lz4 package is not installed") from None
        dec = lz4.frame.LZ4FrameDecompressor()
        try:
            out = dec.decompress(data, max_length=limit + 1)
        except RuntimeError as err:
            raise _Garbage(f"lz4 chunk does not decompress: {err}") from None
    else:
        raise _Garbage(f"unknown chunk compression {compression!r}")
    if len(out) > limit:
        if size is None:
            raise _TooLarge(f"{compression} chunk decompresses to more than {MAX_CHUNK_BYTES >> 20} MiB")
        raise _Garbage(f"{compression} chunk decompresses to more than its declared {size} bytes")
    return out, complete and dec.eof


def _read_record(f: BinaryIO) -> tuple[dict[str, bytes], bytes, bool] | None:
    """Next top-level record: ``(fields, data, complete)``; None at a clean end of file.

    ``complete`` is False when the file ends inside the record's data (the data returned is
    what there is). Raises ``_Cut`` when it ends inside the header, ``_Garbage`` on nonsense.
    """
    head = f.read(4)
    if not head:
        return None
    if len(head) < 4:
        raise _Cut()
    (hlen,) = _u32.unpack(head)
    if hlen > _MAX_HEADER or hlen == 0:
        raise _Garbage(f"record header length {hlen}")
    header = f.read(hlen)
    if len(header) < hlen:
        raise _Cut()
    fields = parse_fields(header)
    raw = f.read(4)
    if len(raw) < 4:
        raise _Cut()
    (dlen,) = _u32.unpack(raw)
    if dlen > MAX_CHUNK_BYTES:
        raise _TooLarge(f"record declares {dlen} bytes of data, beyond the limit of {MAX_CHUNK_BYTES >> 20} MiB")
    data = f.read(dlen)
    return fields, data, len(data) == dlen


def scan_bag(path: str | Path) -> Iterator[RawConnection | RawMessage | ScanEnd]:
    """Walk a ROS 1 bag from its first byte; yield connections and messages in file order.

    The last item is always a :class:`ScanEnd` saying whether the file was complete. The
    walk never raises on damaged content (it ends with status ``"truncated"`` or
    ``"damaged"`` instead); it raises ``OSError`` only when the file cannot be opened, and
    ``ValueError`` when the file is not a ROS 1 v2.0 bag at all.

    Examples
    --------
    >>> for item in scan_bag("cut.bag"):                        # doctest: +SKIP
    ...     if isinstance(item, RawMessage): print(item.conn_id, len(item.data))
    ...     elif isinstance(item, ScanEnd): print(item.status, item.detail)
    """
    path = Path(path)
    size = path.stat().st_size
    with path.open("rb") as f:
        magic = f.read(len(MAGIC))
        if magic != MAGIC:
            raise ValueError(f"{path.name} does not start with {MAGIC!r}; it is not a ROS 1 (v2.0) bag")
        index_pos = 0
        saw_index = False
        chunk_count = chunk_infos = 0  # the index ends with one chunk-info record per chunk
        saw_chunk = False
        seen_conn: set[int] = set()
        while True:
            offset = f.tell()
            try:
                rec = _read_record(f)
            except _Cut:
                yield ScanEnd("truncated", offset, f"the file ends inside a record header at byte {offset} of {size}")
                return
            except _Garbage as err:
                yield ScanEnd("damaged", offset, f"the record at byte {offset} is damaged ({err})")
                return
            except _TooLarge as err:
                yield ScanEnd("too_large", offset, f"the record at byte {offset} is refused: {err}")
                return
            if rec is None:
                # an empty bag (no chunks) has an empty index: nothing to miss
                if saw_index and chunk_infos < chunk_count:
                    yield ScanEnd("truncated", offset, f"the file ends at byte {size} inside its index ({chunk_infos} "
                                                       f"of {chunk_count} chunk records); every message was read")
                elif saw_index or (index_pos > 0 and not saw_chunk):
                    yield ScanEnd("complete", offset, "read the whole bag")
                else:
                    yield ScanEnd("no_index", offset, f"the file ends at byte {size} without the index a closed recording has")
                return
            fields, data, complete = rec
            try:
                op = _op(fields)
                if not complete and op != OP_CHUNK:  # a partial chunk still gives its records; others nothing
                    yield ScanEnd("truncated", offset, f"the file ends inside a record that starts at byte {offset} "
                                                       f"of {size}")
                    return
                if op == OP_BAG_HEADER:
                    index_pos = _uint(fields, "index_pos")
                    chunk_count = _uint(fields, "chunk_count") if "chunk_count" in fields else 0
                elif op == OP_CHUNK:
                    saw_chunk = True
                    compression = fields.get("compression", b"none").decode("ascii", "replace")
                    declared = _uint(fields, "size") if "size" in fields else None
                    inner, inner_complete = _decompress(compression, data, complete, declared)
                    try:
                        for ifields, idata in _records_in(inner):
                            iop = _op(ifields)
                            if iop == OP_CONNECTION:
                                conn = _connection(ifields, idata)
                                if conn.conn_id not in seen_conn:
                                    seen_conn.add(conn.conn_id)
                                    yield conn
                            elif iop == OP_MSG_DATA:
                                yield RawMessage(_uint(ifields, "conn"), _time_ns(ifields), idata)
                    except _Cut:
                        inner_complete = False
                    if not inner_complete:
                        yield ScanEnd("truncated", offset, f"the file ends inside a chunk that starts at byte {offset} of {size}")
                        return
                elif op == OP_CONNECTION:
                    conn = _connection(fields, data)
                    if conn.conn_id not in seen_conn:
                        seen_conn.add(conn.conn_id)
                        yield conn
                    saw_index = saw_index or offset >= index_pos > 0
                elif op == OP_MSG_DATA:  # unchunked message: not written by ROS, tolerated
                    if complete:
                        yield RawMessage(_uint(fields, "conn"), _time_ns(fields), data)
                elif op == OP_CHUNK_INFO:
                    saw_index = True
                    chunk_infos += 1
            except _Garbage as err:
                yield ScanEnd("damaged", offset, f"the record at byte {offset} is damaged ({err})")
                return
            except _TooLarge as err:
                yield ScanEnd("too_large", offset, f"the record at byte {offset} is refused: {err}")
                return
            if not complete:
                yield ScanEnd("truncated", offset, f"the file ends inside a record that starts at byte {offset} of {size}")
                return


__all__ = ["scan_bag", "RawConnection", "RawMessage", "ScanEnd", "MAGIC", "MAX_CHUNK_BYTES", "parse_fields"]
