"""Frames from still-image files (a folder, a glob pattern) and from video files."""

from __future__ import annotations

import glob as _glob
import os
from collections.abc import Iterator
from pathlib import Path

import cv2

from ..errors import FrameError, Reason, SourceError, opencv_message
from .decode import decode_image, read_image_file
from .headers import check_dimensions
from .frame import Frame, FrameSource, error_frame, natural_key

#: file extensions read as still images (lower case)
IMAGE_EXTENSIONS = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".pgm", ".ppm", ".pnm"})
#: consecutive undecodable video frames tried before a video is given up
MAX_VIDEO_GAP = 8
#: file extensions opened with cv2.VideoCapture (lower case)
VIDEO_EXTENSIONS = frozenset({".mp4", ".avi", ".mkv", ".mov", ".m4v", ".webm", ".mpg", ".mpeg", ".wmv", ".ogv", ".mjpg", ".mjpeg"})


def _is_entry(p: Path) -> bool:
    """A folder entry that is a frame candidate: not hidden, not a sub-folder.

    FIFOs, devices, sockets and dangling symlinks are candidates too, so that they show up
    in the tally (``not_a_file`` / ``unreadable``) instead of disappearing silently.
    """
    # hidden files (.DS_Store, ._img.jpg from macOS, .ipynb_checkpoints) are never frames
    if p.name.startswith("."):
        return False
    try:
        return not p.is_dir()
    except OSError:
        return True


def _visible_files(paths: Iterator[Path]) -> list[Path]:
    return sorted((p for p in paths if _is_entry(p)), key=lambda p: natural_key(p.name))


class StillsSource(FrameSource):
    """Still images, one frame per file, in natural order (``img2`` before ``img10``).

    Decision on files that are not images: every visible file is a frame. A file whose
    extension is not an image format (``README.txt``, ``notes.yaml``) becomes a frame with
    error reason ``"not_an_image"`` without being read, so the run's tally shows it instead
    of hiding it; a zero-byte image is ``"empty"``; a damaged one ``"corrupt_jpeg"`` /
    ``"corrupt_image"``; one declaring more pixels than the kit decodes ``"too_large"``; one
    that cannot be read from disk ``"unreadable"``; a FIFO, a device or a symlink to one
    ``"not_a_file"`` (never opened for reading, never waited on). Hidden files (names
    starting with ``.``) and sub-folders are ignored.

    ``kind`` is ``"folder"`` for a folder and ``"glob"`` for a pattern or a single image file.
    """

    is_stream = False

    def __init__(self, spec: str, files: list[Path], kind: str, path: Path | None):
        super().__init__(spec, path)
        self.kind = kind
        self.files = list(files)

    def _length(self) -> int:
        return len(self.files)

    def describe(self) -> str:
        n_img = sum(p.suffix.lower() in IMAGE_EXTENSIONS for p in self.files)
        other = len(self.files) - n_img
        what = f"folder {self.path}" if self.kind == "folder" else f"files matching {self.spec!r}"
        text = f"{what}: {n_img} image files"
        return text + (f" and {other} other files (counted as not_an_image)" if other else "")

    def __iter__(self) -> Iterator[Frame]:
        for index, p in enumerate(self.files):
            name = p.name
            if p.suffix.lower() not in IMAGE_EXTENSIONS:
                yield error_frame(index, float(index), name, Reason.NOT_AN_IMAGE,
                                  f"{name} is not an image file (extension {p.suffix or 'none'}); it is skipped")
                continue
            try:
                image = decode_image(read_image_file(p, name))
            except FrameError as err:
                yield Frame(index=index, stamp=float(index), image=None,
                            error=FrameError(err.reason, f"{name}: {err}"), name=name)
                continue
            yield Frame(index=index, stamp=float(index), image=image, error=None, name=name)


def folder_source(path: Path, spec: str) -> StillsSource:
    """All visible files of a folder (not recursive)."""
    files = _visible_files(path.iterdir())
    if not any(p.suffix.lower() in IMAGE_EXTENSIONS for p in files):
        exts = ", ".join(sorted(IMAGE_EXTENSIONS))
        raise SourceError(
            f"folder {str(path)!r} holds no image files ({len(files)} other files); put the frames there as "
            f"{exts} or pass a bag or a video instead"
        )
    return StillsSource(spec, files, "folder", path)


def glob_source(pattern: str) -> StillsSource:
    """Files matching a glob pattern (``frames/*.png``; ``**`` recurses)."""
    matches = (Path(p) for p in _glob.glob(os.path.expanduser(pattern), recursive=True))
    files = sorted((p for p in matches if _is_entry(p)), key=lambda p: natural_key(str(p)))
    if not files:
        raise SourceError(f"no file matches {pattern!r}; check the pattern (relative to {os.getcwd()}) "
                          "or pass the folder itself")
    return StillsSource(pattern, files, "glob", None)


class VideoSource(FrameSource):
    """Frames of a video file, read with OpenCV's ``VideoCapture``.

    ``stamp`` is ``index / fps`` (the container's frame rate), or the decoder's position in
    milliseconds when the file does not state a frame rate. The number of frames is not known
    for sure before reading (containers lie), so ``len()`` raises ``TypeError``;
    :attr:`estimated_frames` gives the container's claim.
    """

    kind = "video"
    is_stream = True

    def __init__(self, path: Path, spec: str):
        super().__init__(spec, path)
        cap = cv2.VideoCapture(str(path))
        try:
            if not cap.isOpened():
                raise SourceError(
                    f"OpenCV cannot open the video {str(path)!r}; the file is damaged or its codec is not "
                    "supported by this OpenCV build. Convert it (e.g. `ffmpeg -i IN -c:v mjpeg OUT.avi`) or "
                    "extract the frames into a folder of PNGs"
                )
            self.fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
            self.frame_size = (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
            self.estimated_frames = max(int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0), 0)
            try:
                if min(self.frame_size) > 0:
                    check_dimensions(*self.frame_size, f"video {path.name}")
            except FrameError as err:
                raise SourceError(str(err).replace("the frame is skipped", "the video is not read")) from None
        finally:
            cap.release()

    def describe(self) -> str:
        w, h = self.frame_size
        return f"video {self.path.name}, {w}x{h}, {self.fps:g} fps, about {self.estimated_frames} frames"

    def __iter__(self) -> Iterator[Frame]:
        cap = cv2.VideoCapture(str(self.path))
        if not cap.isOpened():
            raise SourceError(f"OpenCV cannot open the video {str(self.path)!r} any more; was it moved or deleted?")
        try:
            index = good = 0
            first_bad = None  # first frame of a run the decoder could not give
            why = ""
            while True:
                pos_ms = cap.get(cv2.CAP_PROP_POS_MSEC)
                try:
                    ok, image = cap.read()
                except cv2.error as err:
                    ok, image, why = False, None, opencv_message(err)
                stamp = index / self.fps if self.fps > 0 else float(pos_ms) / 1000.0
                name = f"{self.path.name}#{index}"
                if not ok or image is None:
                    if first_bad is None and index >= self.estimated_frames:
                        return  # the stated end: a normal end of file
                    if first_bad is None:
                        first_bad, why = index, why or "the decoder returned no picture"
                    index += 1
                    if index - first_bad <= MAX_VIDEO_GAP and index < self.estimated_frames:
                        continue  # FFmpeg often resynchronises after a damaged frame: try the next one
                    lost = max(self.estimated_frames - first_bad, index - first_bad)
                    yield error_frame(
                        first_bad, stamp, f"{self.path.name}#{first_bad}", Reason.VIDEO_DECODE_FAILED,
                        f"video {self.path.name} stops decoding at frame {first_bad} of the {self.estimated_frames} "
                        f"its container states ({why}); {good} frames were read, {lost} are lost. The file is "
                        "damaged: copy or convert it again (e.g. `ffmpeg -i IN -c:v mjpeg OUT.avi`)",
                    )
                    return
                if first_bad is not None:  # one counted frame for each frame the decoder skipped
                    for bad in range(first_bad, index):
                        yield error_frame(
                            bad, bad / self.fps if self.fps > 0 else stamp, f"{self.path.name}#{bad}",
                            Reason.VIDEO_DECODE_FAILED,
                            f"video {self.path.name}: frame {bad} could not be decoded ({why}); decoding resumed at "
                            f"frame {index}",
                        )
                    first_bad, why = None, ""
                good += 1
                if image.size == 0:
                    yield error_frame(index, stamp, name, Reason.EMPTY, f"frame {index} of {self.path.name} is empty")
                else:
                    if image.ndim == 2:
                        image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
                    yield Frame(index=index, stamp=stamp, image=image, error=None, name=name)
                index += 1
        finally:
            cap.release()


__all__ = ["StillsSource", "VideoSource", "folder_source", "glob_source", "IMAGE_EXTENSIONS", "VIDEO_EXTENSIONS"]
