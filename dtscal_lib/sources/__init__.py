"""Camera sources: where the frames of a calibration come from.

One function, :func:`open_source`, turns what the user typed into an iterable of
:class:`Frame`:

======================  =========  ==========  =============================================
spec                    kind       is_stream   frames
======================  =========  ==========  =============================================
``run.bag``             bag        True        one per message of the camera image topic
``run/`` (ROS 2 bag),   bag        True        the same, from a ROS 2 bag's folder or storage file
``run.mcap``, ``.db3``                         (:mod:`.ros2bag`; a DD24-B records these)
``run.mp4`` (.avi ...)  video      True        one per decoded video frame
``frames/``             folder     False       one per visible file, natural order
``frames/*.png``        glob       False       one per matching file, natural order
``img.png``             glob       False       that one image
======================  =========  ==========  =============================================

Bad data never stops a source: a frame that cannot be used comes out with ``image=None``
and an ``error`` (a :class:`~dtscal_lib.errors.FrameError` whose ``reason`` is a
:class:`~dtscal_lib.errors.Reason`),
and the next frame follows. A bag cut short yields every message still readable, then one
last frame with reason ``"truncated"``. Only a source that cannot be opened at all raises
:class:`~dtscal_lib.errors.SourceError`, with a message that says what to pass instead.

Live cameras (a robot over DTPS or ROS 1, a webcam, a stream, a recording played as a camera) are
:func:`~dtscal_lib.sources.live.open_live` in :mod:`dtscal_lib.sources.live`.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from ..errors import SourceError
from .bag import BagSource, list_image_topics, write_compressed_image_bag
from .ros2bag import Ros2BagSource, is_ros2_bag, write_ros2_image_bag
from .decode import decode_image, describe_file_type
from .files import IMAGE_EXTENSIONS, VIDEO_EXTENSIONS, StillsSource, VideoSource, folder_source, glob_source
from .frame import Frame, FrameSource
from .live import LiveSource, LiveStatus, open_live

_GLOB_CHARS = set("*?[")


def open_source(spec: str | os.PathLike, *, topic: str | None = None) -> FrameSource:
    """Open a recording or a set of images as a :class:`FrameSource`.

    Parameters
    ----------
    spec : path of a ROS 1 bag (``.bag``), a video file, a folder of images, a single image,
        or a glob pattern such as ``"frames/*.png"``
    topic : bag topic to read; by default the one ending in ``/image/compressed`` (or the only
        image topic). Only meaningful for bags.

    Returns
    -------
    FrameSource
        Iterable of :class:`Frame`; ``len()`` works for bags, folders and globs.

    Raises
    ------
    SourceError
        Missing path, unknown file type, bag without image topic or without ``topic``,
        video OpenCV cannot open, folder without images, pattern matching nothing.

    Examples
    --------
    >>> src = open_source("recordings/intrinsics.bag")                  # doctest: +SKIP
    >>> good = [f.image for f in src if f.ok]                          # doctest: +SKIP
    """
    if isinstance(spec, (bytes, bytearray)):
        spec = os.fsdecode(spec)
    if not isinstance(spec, (str, os.PathLike)):
        raise SourceError(f"a source is a path or a glob pattern (str), got {type(spec).__name__}")
    text = os.fspath(spec)
    if not text.strip():
        raise SourceError("empty source; pass a .bag file, a video, a folder of images or a glob like 'frames/*.png'")
    path = Path(os.path.expanduser(text))

    def no_topic(kind: str) -> None:
        if topic is not None:
            raise SourceError(f"--topic {topic!r} only applies to ROS bags, but {text!r} is a {kind}; drop --topic "
                              "(topic= in Python)")

    if not path.exists():
        if _GLOB_CHARS & set(text):
            no_topic("glob pattern")
            return glob_source(text)
        hint = ""
        parent = path.parent
        if parent.is_dir():
            near = sorted(p.name for p in parent.iterdir()
                          if p.suffix.lower() in {".bag", ".mcap", ".db3"} | VIDEO_EXTENSIONS)[:5]
            if near:
                hint = f"; recordings in {str(parent)!r}: {', '.join(near)}"
        raise SourceError(f"source {text!r} does not exist (looked in {os.getcwd()}){hint}")
    if is_ros2_bag(path):
        if not path.is_dir():
            _check_regular_file(path, text)
        return Ros2BagSource(path, topic=topic, spec=text)
    if path.is_dir():
        no_topic("folder")
        return folder_source(path, text)
    _check_regular_file(path, text)
    ext = path.suffix.lower()
    if ext == ".bag" or _starts_like_bag(path):
        return BagSource(path, topic=topic, spec=text)
    if ext in VIDEO_EXTENSIONS:
        no_topic("video")
        return VideoSource(path, text)
    if ext in IMAGE_EXTENSIONS:
        no_topic("image file")
        return StillsSource(text, [path], "glob", path)
    raise SourceError(
        f"do not know how to read {path.name!r} (extension {ext or 'none'}); pass a ROS 1 bag (.bag), a ROS 2 bag "
        "(its folder, or a .mcap / .db3 file), a video "
        f"({', '.join(sorted(VIDEO_EXTENSIONS))}), a folder of images or a glob pattern like 'frames/*.png'"
    )


def _check_regular_file(path: Path, text: str) -> None:
    """Refuse a FIFO, a device, a socket (or a symlink to one) before anything opens it.

    Opening a FIFO for reading blocks until a writer comes; ``/dev/zero`` never ends.
    """
    try:
        mode = path.stat().st_mode
    except OSError as err:
        raise SourceError(f"cannot read source {text!r}: {err.strerror}") from None
    if not stat.S_ISREG(mode):
        raise SourceError(f"source {text!r} is {describe_file_type(mode)}, not a regular file; pass a recording saved "
                          "as a file (a .bag, a video), a folder of images or a glob pattern")


def _starts_like_bag(path: Path) -> bool:
    try:
        with path.open("rb") as f:
            return f.read(9) == b"#ROSBAG V"
    except OSError:
        return False


__all__ = [
    "Frame",
    "FrameSource",
    "BagSource",
    "Ros2BagSource",
    "write_ros2_image_bag",
    "VideoSource",
    "StillsSource",
    "open_source",
    "decode_image",
    "write_compressed_image_bag",
    "list_image_topics",
    "LiveSource",
    "LiveStatus",
    "open_live",
]
