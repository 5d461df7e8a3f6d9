"""ROS 1 bags: read camera frames from them, write them.

Messages are read by the bounded sequential reader of :mod:`.bagformat` (the one bag
reader of the kit) and deserialized with ``rosbags``' ROS 1 Noetic type store (pure
Python, no ROS install needed). ``rosbags`` reads the index only, for the topics and the
message counts; when it refuses a bag because its index is missing (a file cut short, a
recording that was killed) the sequential walk finds them instead. Every message before
damage is still yielded, followed by one frame with error reason ``"truncated"`` (or
``"too_large"`` for a decompression bomb) that says how many frames were read.
"""

from __future__ import annotations

import os
import stat
from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import safe_write
from .. import duckietown as dt
from ..errors import FrameError, Reason, SourceError
from .bagformat import MAGIC, RawConnection, RawMessage, ScanEnd, scan_bag
from .decode import decode_image, describe_file_type, raw_image_to_bgr
from .frame import Frame, FrameSource, error_frame

COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
RAW_IMAGE = "sensor_msgs/msg/Image"
IMAGE_TYPES = (COMPRESSED_IMAGE, RAW_IMAGE)
#: the Duckiebot camera topic ends like this
CAMERA_TOPIC_SUFFIX = dt.IMAGE_SUFFIX


def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC)


def normalize_msgtype(name: str) -> str:
    """``sensor_msgs/CompressedImage`` (ROS 1 spelling) -> ``sensor_msgs/msg/CompressedImage``."""
    parts = name.split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return name


def _ros1_name(msgtype: str) -> str:
    return msgtype.replace("/msg/", "/")


@dataclass(frozen=True)
class BagInfo:
    """What a bag holds, read once when it is opened.

    topics : {topic: normalized message type}
    counts : {topic: messages readable}
    end : None when ``rosbags`` read the index; the sequential walk's end otherwise.
    """

    topics: dict[str, str]
    counts: dict[str, int]
    end: ScanEnd | None

    @property
    def image_topics(self) -> list[str]:
        return sorted(t for t, ty in self.topics.items() if ty in IMAGE_TYPES)

    @property
    def indexed(self) -> bool:
        return self.end is None


def _check_bag_file(path: Path) -> None:
    if not path.exists():
        raise SourceError(f"bag file {str(path)!r} does not exist; check the path (relative paths start at {os.getcwd()})")
    mode = path.stat().st_mode
    if not stat.S_ISREG(mode):
        raise SourceError(f"{str(path)!r} is {describe_file_type(mode)}, not a ROS 1 bag file; pass the recording "
                          "saved as a file")
    try:
        with path.open("rb") as f:
            head = f.read(len(MAGIC))
    except OSError as err:
        raise SourceError(f"cannot read bag {str(path)!r}: {err.strerror}; check its permissions") from None
    if head != MAGIC:
        if not head:
            raise SourceError(f"{path.name} is empty (0 bytes); copy the recording again")
        if MAGIC.startswith(head):
            raise SourceError(f"{path.name} is cut short after {len(head)} bytes; copy the recording again")
        if head.startswith(b"#ROSBAG V"):
            raise SourceError(
                f"{path.name} is a ROS bag of version {head[9:12].decode('ascii', 'replace')}; only v2.0 "
                "(ROS 1 since Groovy) is read. Migrate it with `rosbag fix` first"
            )
        raise SourceError(
            f"{path.name} is not a ROS 1 bag (it does not start with '#ROSBAG V2.0'); for a ROS 2 "
            "recording, convert it with `rosbags-convert`; for a video pass a .mp4/.avi file"
        )


#: the smallest message record of a ROS 1 bag: header length (4) and data length (4), and the header's
#: three fields, each a 4-byte length and ``name=value``: op (3 + 1), conn (5 + 4), time (5 + 8) bytes
#: (ROS's Bag format 2.0, "Message data" record): an index counting more messages than this allows is damaged
MIN_MESSAGE_RECORD_BYTES = 4 + 4 + (4 + 3 + 1) + (4 + 5 + 4) + (4 + 5 + 8)


def message_frame(bag_name: str, topic: str, msgtype: str, deserialize, index: int, data, time_ns: int) -> Frame:
    """One camera message of a bag (ROS 1 or ROS 2: ``deserialize(data, msgtype)``) as a frame, through the kit's
    one decode path; a message that does not deserialize or decode is this frame's error only."""
    name = f"{bag_name}#{index}"
    stamp = time_ns * 1e-9
    try:
        msg = deserialize(data, msgtype)
    except Exception as err:  # noqa: BLE001 - any decoding failure is this frame's problem only
        return error_frame(index, stamp, name, Reason.UNREADABLE,
                           f"message {index} on {topic} is not a valid {_ros1_name(msgtype)} ({err})")
    hs = msg.header.stamp
    if hs.sec or hs.nanosec:
        stamp = hs.sec + hs.nanosec * 1e-9
    try:
        if msgtype == COMPRESSED_IMAGE:
            image = decode_image(bytes(msg.data))
        else:
            image = raw_image_to_bgr(msg.height, msg.width, msg.encoding, msg.step, msg.data)
    except FrameError as err:
        return Frame(index=index, stamp=stamp, image=None, error=err, name=name)
    return Frame(index=index, stamp=stamp, image=image, error=None, name=name)


def read_bag_info(path: str | os.PathLike) -> BagInfo:
    """Topics, types and message counts of a bag; falls back to a sequential walk.

    Raises
    ------
    SourceError
        The file is missing, unreadable, or not a ROS 1 v2.0 bag.
    """
    path = Path(path)
    _check_bag_file(path)
    from rosbags.rosbag1 import Reader, ReaderError

    try:
        with Reader(path) as reader:
            topics: dict[str, str] = {}
            counts: dict[str, int] = {}
            for topic, info in reader.topics.items():
                types = {normalize_msgtype(c.msgtype) for c in info.connections}
                topics[topic] = types.pop() if len(types) == 1 else "(mixed types)"
                counts[topic] = int(info.msgcount)
            if sum(counts.values()) * MIN_MESSAGE_RECORD_BYTES <= path.stat().st_size:
                return BagInfo(topics, counts, None)
            # an index that counts more messages than the file can hold is damaged: count by walking
    except ReaderError:
        pass  # no usable index (cut short, recording killed): walk the file instead
    except Exception:  # noqa: BLE001 - rosbags raises struct/Key/Index errors on some damaged indexes
        pass
    conns: dict[int, RawConnection] = {}
    per_conn: Counter = Counter()
    end: ScanEnd | None = None
    for item in scan_bag(path):
        if isinstance(item, RawConnection):
            conns[item.conn_id] = item
        elif isinstance(item, RawMessage):
            per_conn[item.conn_id] += 1
        else:
            end = item
    topics = {c.topic: normalize_msgtype(c.msgtype) for c in conns.values()}
    counts = Counter()
    for cid, n in per_conn.items():
        if cid in conns:
            counts[conns[cid].topic] += n
    return BagInfo(topics, {t: counts.get(t, 0) for t in topics}, end)


def list_image_topics(bag_path: str | os.PathLike) -> list[str]:
    """Topics of a ROS 1 bag that carry ``sensor_msgs/CompressedImage`` or ``sensor_msgs/Image``.

    Works on truncated bags too (their topics are found by walking the file).

    Returns
    -------
    Sorted list of topic names, possibly empty.
    """
    return read_bag_info(bag_path).image_topics


def choose_image_topic(info: BagInfo, topic: str | None, bag_name: str) -> str:
    """The topic to read: ``topic`` if given and valid, else the camera topic of the bag."""
    listing = ", ".join(f"{t} ({_ros1_name(ty)})" for t, ty in sorted(info.topics.items())) or "none"
    images = info.image_topics
    if topic is not None:
        if topic in info.topics:
            if info.topics[topic] not in IMAGE_TYPES:
                raise SourceError(
                    f"topic {topic!r} in {bag_name} carries {_ros1_name(info.topics[topic])}, not camera images; "
                    f"image topics in this bag: {', '.join(images) or 'none'}"
                )
            return topic
        hint = f"pass one of: {', '.join(images)}" if images else "this bag has no image topic at all"
        raise SourceError(f"topic {topic!r} is not in {bag_name}; {hint}. All topics: {listing}")
    if not images and info.end is not None and info.end.status != "complete":
        what = {"too_large": "holds more data than the kit reads at once", "damaged": "is damaged"}.get(
            info.end.status, "is cut short")
        raise SourceError(
            f"{bag_name} {what} before any camera topic could be read ({info.end.detail}; topics found: "
            f"{listing}); copy the recording from the robot again"
        )
    if not images:
        raise SourceError(
            f"{bag_name} has no sensor_msgs/CompressedImage or sensor_msgs/Image topic (topics: {listing}); "
            f"record the camera with `rosbag record {dt.ros_name(dt.IMAGE_TOPIC, 'ROBOT')}`"
        )
    camera = [t for t in images if t.endswith(CAMERA_TOPIC_SUFFIX)]
    if len(camera) == 1:
        return camera[0]
    if len(images) == 1:
        return images[0]
    choices = camera or images
    raise SourceError(f"{bag_name} has several image topics ({', '.join(choices)}); choose one with --topic "
                      "(topic= in Python)")


class BagSource(FrameSource):
    """Camera frames from one image topic of a ROS 1 bag.

    Attributes (beyond :class:`FrameSource`)
    ----------------------------------------
    topic : the topic read
    msgtype : ``"sensor_msgs/msg/CompressedImage"`` or ``"sensor_msgs/msg/Image"``
    info : :class:`BagInfo` of the whole bag
    truncated : True when the bag lacks its index or is cut short; iteration then ends with
        one frame of error reason ``"truncated"`` (counted in ``len``)
    """

    kind = "bag"
    is_stream = True

    def __init__(self, path: str | os.PathLike, *, topic: str | None = None, spec: str | None = None):
        path = Path(path)
        super().__init__(spec if spec is not None else str(path), path)
        self.info = read_bag_info(path)
        self.topic = choose_image_topic(self.info, topic, path.name)
        self.msgtype = self.info.topics[self.topic]

    @property
    def truncated(self) -> bool:
        return self.info.end is not None and self.info.end.status != "complete"

    def _length(self) -> int:
        return self.info.counts.get(self.topic, 0) + (1 if self.truncated else 0)

    def describe(self) -> str:
        n = self.info.counts.get(self.topic, 0)
        text = f"ROS bag {self.path.name}, topic {self.topic} ({_ros1_name(self.msgtype)}), {n} frames"
        if self.truncated:
            text += f" readable; {self.info.end.detail}"
        return text

    # --- iteration ---
    def _frame(self, typestore, index: int, data: bytes, time_ns: int) -> Frame:
        return message_frame(self.path.name, self.topic, self.msgtype, typestore.deserialize_ros1, index, data,
                             time_ns)

    def _messages_sequential(self) -> Iterator[tuple[bytes, int] | ScanEnd]:
        wanted: set[int] = set()
        for item in scan_bag(self.path):
            if isinstance(item, RawConnection):
                if item.topic == self.topic:
                    wanted.add(item.conn_id)
            elif isinstance(item, RawMessage):
                if item.conn_id in wanted:
                    yield item.data, item.time_ns
            elif item.status != "complete" and not (self.info.indexed and item.status == "no_index"):
                yield item

    def compressed_images(self) -> Iterator[tuple[int, int, bytes]]:
        """``(index, header stamp in ns, encoded bytes)`` of every message of a CompressedImage topic.

        The raw payloads, undecoded, read by the same bounded reader as the frames.

        Raises
        ------
        SourceError
            The topic is not ``sensor_msgs/CompressedImage``, a message does not deserialize,
            or the bag ends damaged or cut short.
        """
        if self.msgtype != COMPRESSED_IMAGE:
            raise SourceError(f"topic {self.topic} of {self.path.name} carries {_ros1_name(self.msgtype)}, "
                              "not sensor_msgs/CompressedImage")
        typestore = _typestore()
        index = 0
        for item in self._messages_sequential():
            if isinstance(item, ScanEnd):
                raise SourceError(f"bag {self.path.name} ends badly after {index} messages of {self.topic}: "
                                  f"{item.detail}")
            data, time_ns = item
            try:
                msg = typestore.deserialize_ros1(data, self.msgtype)
            except Exception as err:  # noqa: BLE001 - rosbags raises many types on malformed bytes
                raise SourceError(f"message {index} on {self.topic} of {self.path.name} is not a valid "
                                  f"CompressedImage ({type(err).__name__})") from None
            stamp = int(msg.header.stamp.sec) * 10**9 + int(msg.header.stamp.nanosec)
            yield index, stamp, bytes(msg.data)
            index += 1

    def __iter__(self) -> Iterator[Frame]:
        typestore = _typestore()
        messages = self._messages_sequential()
        index = 0
        last_stamp = 0.0
        for item in messages:
            if isinstance(item, ScanEnd):
                reason = {"damaged": Reason.UNREADABLE,
                          "too_large": Reason.TOO_LARGE}.get(item.status, Reason.TRUNCATED)
                what = {
                    "truncated": "is truncated (cut short)",
                    "no_index": "has no index (the recording was not closed, or the copy was cut short)",
                    "damaged": "is damaged",
                    "too_large": "holds more data than the kit reads at once (a damaged or hostile file)",
                }[item.status]
                advice = ("run `rosbag reindex` on it to make it a normal bag, or copy the recording from the robot "
                          "again" if item.status == "no_index" else
                          "if this is a copy, copy the recording from the robot again")
                yield error_frame(
                    index, last_stamp, f"{self.path.name}#{index}", reason,
                    f"bag {self.path.name} {what}: {item.detail}; read {index} frames of {self.topic} "
                    f"before that, the rest is lost; {advice}",
                )
                return
            data, time_ns = item
            frame = self._frame(typestore, index, data, time_ns)
            last_stamp = frame.stamp
            yield frame
            index += 1


def _as_bytes(data, i: int) -> bytes:
    if isinstance(data, (bytes, bytearray, memoryview)):
        return bytes(data)
    if isinstance(data, np.ndarray) and data.dtype == np.uint8:
        return data.reshape(-1).tobytes()
    raise SourceError(f"frame {i}: image data must be bytes (an encoded JPEG), got {type(data).__name__}; "
                      "encode images with cv2.imencode('.jpg', img)[1].tobytes()")


def write_compressed_image_bag(
    path: str | os.PathLike,
    topic: str,
    frames: Iterable[tuple[int, bytes]],
    *,
    frame_id: str = "",
    chunk_threshold: int = 768 * 1024,
) -> Path:
    """Write JPEG frames as a ROS 1 bag (v2.0) of ``sensor_msgs/CompressedImage``, format ``"jpeg"``.

    The bag is what ``rosbag record /ROBOT/camera_node/image/compressed`` would have written:
    ``rosbag play`` publishes it and ``rosbag info`` reads it. The file is written under a
    temporary name and renamed into place, so ``path`` is never left half-written (an
    existing file is replaced).

    Parameters
    ----------
    path : output file, conventionally ending in ``.bag``
    topic : absolute topic name, e.g. ``"/autobot01/camera_node/image/compressed"``
    frames : iterable of ``(stamp_ns, jpeg_bytes)``; ``stamp_ns`` (int, >= 0, non-decreasing is
        usual) becomes both the header stamp and the record time; the bytes are stored as given
        (nothing is checked, so broken data can be written on purpose for tests)
    frame_id : header ``frame_id`` of every message
    chunk_threshold : start a new chunk once one holds this many bytes (ROS's default is 768 KiB)

    Returns
    -------
    The path written, as a :class:`pathlib.Path`.

    Raises
    ------
    SourceError
        Bad topic name, bad stamp or non-bytes data; nothing is left on disk then.

    Examples
    --------
    >>> ok, jpg = cv2.imencode(".jpg", img)                               # doctest: +SKIP
    >>> write_compressed_image_bag("one.bag", "/bot/camera_node/image/compressed",
    ...                            [(0, jpg.tobytes())])                 # doctest: +SKIP
    """
    from rosbags.rosbag1 import Writer

    path = Path(path)
    if not isinstance(topic, str) or not topic.startswith("/") or len(topic) < 2 or " " in topic:
        raise SourceError(f"topic must be an absolute ROS name like '{dt.ros_name(dt.IMAGE_TOPIC, 'ROBOT')}', got {topic!r}")
    if chunk_threshold < 1:
        raise SourceError(f"chunk_threshold must be a positive number of bytes, got {chunk_threshold}")
    if path.is_dir():
        raise SourceError(f"{str(path)!r} is a folder; pass a file name ending in .bag")
    typestore = _typestore()
    CompressedImage = typestore.types[COMPRESSED_IMAGE]
    Header = typestore.types["std_msgs/msg/Header"]
    Time = typestore.types["builtin_interfaces/msg/Time"]
    with safe_write.output(path, what="recording", suffix=".bag") as tmp:
        tmp.unlink()  # rosbags' Writer makes the file itself and refuses one that exists
        writer = Writer(tmp)
        writer.chunk_threshold = int(chunk_threshold)
        with writer:
            conn = writer.add_connection(topic, COMPRESSED_IMAGE, typestore=typestore)
            for i, item in enumerate(frames):
                try:
                    stamp_ns, data = item
                except (TypeError, ValueError):
                    raise SourceError(f"frame {i}: expected a (stamp_ns, jpeg_bytes) pair, got {type(item).__name__}") from None
                if isinstance(stamp_ns, bool) or not isinstance(stamp_ns, (int, np.integer)) or not 0 <= stamp_ns < 2**32 * 10**9:
                    raise SourceError(f"frame {i}: stamp_ns must be an int of nanoseconds >= 0, got {stamp_ns!r}")
                stamp_ns = int(stamp_ns)
                payload = np.frombuffer(_as_bytes(data, i), dtype=np.uint8)
                msg = CompressedImage(
                    header=Header(seq=i, stamp=Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id=frame_id),
                    format="jpeg",
                    data=payload,
                )
                writer.write(conn, stamp_ns, typestore.serialize_ros1(msg, COMPRESSED_IMAGE))
    return path


__all__ = [
    "BagSource",
    "BagInfo",
    "read_bag_info",
    "list_image_topics",
    "choose_image_topic",
    "write_compressed_image_bag",
    "normalize_msgtype",
    "IMAGE_TYPES",
    "COMPRESSED_IMAGE",
    "RAW_IMAGE",
]
