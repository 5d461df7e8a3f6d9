"""The two types every camera source shares: :class:`Frame` and :class:`FrameSource`."""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import FrameError, Reason


@dataclass
class Frame:
    """One frame of a camera source, usable or not.

    A source never stops on a bad frame: it yields a ``Frame`` whose ``image`` is ``None``
    and whose ``error`` says why, and goes on with the next one.

    Attributes
    ----------
    index : int
        0-based position of the frame in the source.
    stamp : float
        Seconds: the message header stamp for a bag (its record time when the header
        stamp is zero), the position in a video, the file's position in a folder.
    image : (H, W, 3) uint8 BGR array, or None
        The decoded picture; ``None`` exactly when ``error`` is set.
    error : FrameError or None
        Why the frame is unusable; ``error.reason`` is a :class:`~dtscal_lib.errors.Reason`
        (a string enum: ``"corrupt_jpeg"``, ``"empty"``, ``"too_large"``, ``"not_a_file"``,
        ``"truncated"``, ...).
    name : str
        Human-readable origin, e.g. ``"intrinsics.bag#17"`` or ``"img_003.png"``.
    arrival : float or None
        Live sources: when the frame arrived in this process (``time.time()``, before decoding);
        the live tools stamp their images with it to measure the latency to the browser.
    """

    index: int
    stamp: float
    image: np.ndarray | None
    error: FrameError | None
    name: str
    arrival: float | None = None

    def __post_init__(self):
        if self.image is None and self.error is None:  # every unusable frame says why
            self.error = FrameError(Reason.UNREADABLE, f"{self.name}: the source gave no image")

    @property
    def ok(self) -> bool:
        """True when the frame decoded to an image."""
        return self.error is None and self.image is not None


class FrameSource:
    """An iterable of :class:`Frame` read from a recording or a set of files.

    Every iteration starts from the first frame again (the source re-opens its file).

    Attributes
    ----------
    kind : str
        ``"bag"``, ``"video"``, ``"folder"`` or ``"glob"``.
    is_stream : bool
        True for recordings (bag, video), where consecutive frames are near duplicates and
        ROS's coverage rule picks the samples; False for a set of still images.
    path : pathlib.Path or None
        The file or folder read (None for a glob pattern).
    spec : str
        What was passed to :func:`open_source`.
    topic : str or None
        The bag topic read (None for other kinds).
    """

    kind: str = ""
    is_stream: bool = False
    topic: str | None = None

    def __init__(self, spec: str, path: Path | None):
        self.spec = spec
        self.path = path

    def __iter__(self) -> Iterator[Frame]:  # pragma: no cover - abstract
        raise NotImplementedError

    def __len__(self) -> int:
        n = self._length()
        if n is None:
            raise TypeError(
                f"the number of frames of {self.describe()} is not known before reading it; "
                "iterate over the source to count them"
            )
        return n

    def _length(self) -> int | None:
        """Frames an iteration yields, when known before reading."""
        return None

    def describe(self) -> str:  # pragma: no cover - abstract
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.describe()}>"


def natural_key(name: str) -> tuple:
    """Sort key that orders ``img2`` before ``img10`` (digits compare as numbers)."""
    parts = re.split(r"(\d+)", name)
    return tuple((0, int(p), p) if p.isdigit() else (1, 0, p.lower()) for p in parts)


def error_frame(index: int, stamp: float, name: str, reason: "Reason | str", message: str) -> Frame:
    """A :class:`Frame` that carries only an error."""
    return Frame(index=index, stamp=stamp, image=None, error=FrameError(reason, message), name=name)


__all__ = ["Frame", "FrameSource", "natural_key", "error_frame"]
