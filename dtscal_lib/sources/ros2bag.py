"""ROS 2 recordings: a bag folder (``metadata.yaml`` beside its storage) or one ``.mcap`` / ``.db3`` file.

A DD24-B records ROS 2 bags (its default stack is ROS 2 Jazzy; ``duckietown.md``). PyPI's ``rosbags``
reads both storage formats (``rosbags.rosbag2.Reader``: MCAP and SQLite 3) and deserializes CDR with its
ROS 2 Jazzy type store; no ROS install is needed. The camera topic is chosen as in a ROS 1 bag
(:func:`~dtscal_lib.sources.bag.choose_image_topic`: ``sensor_msgs/CompressedImage`` or ``sensor_msgs/Image``),
each frame goes through the kit's one guarded decode path, and a ``sensor_msgs/CameraInfo`` topic, when the
bag has one, is read into :attr:`Ros2BagSource.camera_info` (the camera's K, D, size and model).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

from ..errors import SourceError
from .bag import COMPRESSED_IMAGE, BagInfo, _ros1_name, choose_image_topic, message_frame
from .decode import decode_image
from .frame import Frame, FrameSource

CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
#: what a ROS 2 bag's storage file ends in (rosbags.rosbag2.Reader.STORAGE_PLUGINS)
ROS2_EXTENSIONS = (".mcap", ".db3")


def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def is_ros2_bag(path: Path) -> bool:
    """A ROS 2 bag folder (``metadata.yaml``) or a ``.mcap`` / ``.db3`` file."""
    return (path.is_dir() and (path / "metadata.yaml").is_file()) or path.suffix.lower() in ROS2_EXTENSIONS


def _reader(path: Path):
    from rosbags.rosbag2 import Reader

    try:
        reader = Reader(path)
        reader.open()
    except Exception as exc:  # noqa: BLE001 - rosbags raises its own, sqlite's, yaml's and struct errors
        raise SourceError(f"cannot read the ROS 2 bag {path.name} ({type(exc).__name__}: {exc}); copy the recording "
                          "from the robot again, or record it with `ros2 bag record`") from None
    return reader


class Ros2BagSource(FrameSource):
    """Camera frames from one image topic of a ROS 2 bag (see module doc)."""

    kind = "bag"
    is_stream = True

    def __init__(self, path: str | os.PathLike, *, topic: str | None = None, spec: str | None = None):
        path = Path(path)
        super().__init__(spec if spec is not None else str(path), path)
        reader = _reader(path)
        try:
            topics = {c.topic: c.msgtype for c in reader.connections}
            counts: dict[str, int] = {}
            for c in reader.connections:
                counts[c.topic] = counts.get(c.topic, 0) + c.msgcount
            self.info = BagInfo(topics, counts, None)
            self.topic = choose_image_topic(self.info, topic, path.name)
            self.msgtype = topics[self.topic]
            #: the bag's ``sensor_msgs/CameraInfo`` (first message), or None
            self.camera_info = self._camera_info(reader)
        finally:
            reader.close()

    @staticmethod
    def _camera_info(reader) -> dict | None:
        conns = [c for c in reader.connections if c.msgtype == CAMERA_INFO]
        if not conns:
            return None
        for conn, _t, data in reader.messages(connections=conns[:1]):
            try:
                msg = _typestore().deserialize_cdr(data, conn.msgtype)
            except Exception:  # noqa: BLE001 - a damaged camera_info is only not used
                return None
            return {"topic": conn.topic, "width": int(msg.width), "height": int(msg.height),
                    "distortion_model": str(msg.distortion_model), "K": [float(v) for v in msg.k],
                    "D": [float(v) for v in msg.d], "P": [float(v) for v in msg.p]}
        return None

    def _length(self) -> int:
        return self.info.counts.get(self.topic, 0)

    def describe(self) -> str:
        n = self.info.counts.get(self.topic, 0)
        text = f"ROS 2 bag {self.path.name}, topic {self.topic} ({_ros1_name(self.msgtype)}), {n} frames"
        if self.camera_info:
            text += f", camera_info on {self.camera_info['topic']}"
        return text

    def _frame(self, typestore, index: int, data, time_ns: int) -> Frame:
        return message_frame(self.path.name, self.topic, self.msgtype, typestore.deserialize_cdr, index, data,
                             time_ns)

    def __iter__(self) -> Iterator[Frame]:
        typestore = _typestore()
        reader = _reader(self.path)
        try:
            conns = [c for c in reader.connections if c.topic == self.topic]
            for index, (_conn, time_ns, data) in enumerate(reader.messages(connections=conns)):
                yield self._frame(typestore, index, data, time_ns)
        finally:
            reader.close()


def write_ros2_image_bag(path, topic: str, frames, *, storage: str = "mcap", raw: bool = False,
                         camera_info: dict | None = None) -> Path:
    """Write ``frames`` (``(stamp_ns, jpeg bytes)``) as a ROS 2 bag folder with ``rosbags``' writer.

    ``storage`` is ``"mcap"`` or ``"sqlite3"`` (a ``.db3``); ``raw=True`` stores decoded ``sensor_msgs/Image``
    (``bgr8``) instead of the JPEGs; ``camera_info`` (``width``, ``height``, ``K``, ``D``, ``P``) adds a
    ``camera_info`` topic beside the images. Returns the bag folder.
    """
    import numpy as np
    from rosbags.rosbag2 import StoragePlugin, Writer

    ts = _typestore()
    types = ts.types
    Header, Time = types["std_msgs/msg/Header"], types["builtin_interfaces/msg/Time"]
    plugin = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}[storage]
    path = Path(path)
    with Writer(path, version=9, storage_plugin=plugin) as writer:
        msgtype = "sensor_msgs/msg/Image" if raw else COMPRESSED_IMAGE
        conn = writer.add_connection(topic, msgtype, typestore=ts)
        info_conn = (writer.add_connection(topic.rsplit("/", 2)[0] + "/camera_info", CAMERA_INFO, typestore=ts)
                     if camera_info else None)
        for stamp_ns, data in frames:
            header = Header(stamp=Time(sec=int(stamp_ns // 10**9), nanosec=int(stamp_ns % 10**9)),
                            frame_id="camera_optical_frame")
            if raw:
                img = decode_image(data)
                msg = types[msgtype](header=header, height=img.shape[0], width=img.shape[1], encoding="bgr8",
                                     is_bigendian=0, step=img.shape[1] * 3, data=img.reshape(-1))
            else:
                msg = types[msgtype](header=header, format="jpeg", data=np.frombuffer(data, np.uint8))
            writer.write(conn, stamp_ns, ts.serialize_cdr(msg, msgtype))
            if info_conn is not None:
                roi = types["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0,
                                                                 do_rectify=False)
                info = types[CAMERA_INFO](
                    header=header, height=camera_info["height"], width=camera_info["width"],
                    distortion_model="plumb_bob", d=np.asarray(camera_info["D"], float),
                    k=np.asarray(camera_info["K"], float), r=np.eye(3).ravel(), p=np.asarray(camera_info["P"], float),
                    binning_x=0, binning_y=0, roi=roi)
                writer.write(info_conn, stamp_ns, ts.serialize_cdr(info, CAMERA_INFO))
    return path
