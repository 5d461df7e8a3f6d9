"""Fuzz the three parsers that read untrusted bytes: image headers, bag records, YAML documents.

Run by tests/test_hostile_input.py in a subprocess capped at 1 GB of address space (so a parser
that allocates without bound fails the test, not the machine); also runnable by hand::

    .venv/bin/python tests/hostile_fuzz.py

The contract checked on every example: the input either gives a result within the kit's limits
or is refused with the kit's own error (``FrameError`` / ``SourceError`` /
``CalibrationFileError``) — never another exception, never unbounded memory. Hypothesis is
derandomized (the same examples on every run, so CI is reproducible) and sized to finish in
well under the two minutes CI allows.
"""

from __future__ import annotations

import struct
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

import hostile  # noqa: E402
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from dtscal_lib import calib_files  # noqa: E402
from dtscal_lib.errors import CalibrationFileError, FrameError, Reason, SourceError  # noqa: E402
from dtscal_lib.sources import decode_image, open_source  # noqa: E402
from dtscal_lib.sources.headers import MAX_PIXELS, MAX_SIDE  # noqa: E402

FUZZ = settings(derandomize=True, database=None, deadline=None, print_blob=True,
                suppress_health_check=list(HealthCheck))

# --------------------------------------------------------------------------- image headers
IMAGE_BASES = {ext: hostile.encode(ext) for ext in (".jpg", ".png", ".bmp", ".ppm", ".tiff", ".webp")}
IMAGE_BASES[".pgm"] = hostile.encode(".pgm", hostile.small_image()[:, :, 0].copy())


def _with_size(ext: str, data: bytes, w: int, h: int) -> bytes:
    """The encoded image with its header's width and height replaced."""
    if ext == ".jpg":
        return hostile.jpeg_claiming(data, w & 0xFFFF, h & 0xFFFF)
    if ext == ".png":
        return data[:16] + struct.pack(">II", w, h) + data[24:]
    if ext == ".bmp":
        return data[:18] + struct.pack("<ii", w - (1 << 31), h - (1 << 31)) + data[26:]
    if ext in (".ppm", ".pgm"):
        body = data.split(b"\n", 3)[3]
        return data[:2] + f"\n{w} {h}\n255\n".encode() + body
    return data


@given(ext=st.sampled_from(sorted(IMAGE_BASES)),
       edits=st.lists(st.tuples(st.integers(0, 1 << 16), st.integers(0, 255)), max_size=6),
       head_edits=st.lists(st.tuples(st.integers(0, 40), st.integers(0, 255)), max_size=4),
       size=st.none() | st.tuples(st.integers(0, (1 << 32) - 1), st.integers(0, (1 << 32) - 1)),
       cut=st.integers(0, 1 << 12))
def fuzz_image(ext, edits, head_edits, size, cut):
    data = IMAGE_BASES[ext]
    if size is not None:
        data = _with_size(ext, data, *size)
    b = bytearray(data)
    for pos, val in edits + head_edits:
        if pos < len(b):
            b[pos] = val
    if 0 < cut < len(b):
        del b[-cut:]
    try:
        img = decode_image(bytes(b))
    except FrameError as err:
        assert isinstance(err.reason, Reason), err.reason
        assert len(str(err)) < 600
        return
    assert img.ndim == 3 and img.shape[2] == 3 and img.dtype.name == "uint8"
    assert max(img.shape[:2]) <= MAX_SIDE and img.shape[0] * img.shape[1] <= MAX_PIXELS


# --------------------------------------------------------------------------- bag records
_TMP = Path(tempfile.mkdtemp(prefix="dtscal-fuzz-"))
_JPEGS = [hostile.encode(".jpg", hostile.small_image(32, 24)) for _ in range(3)]
BAG = hostile.write_bag(_TMP / "base.bag", _JPEGS).read_bytes()
BAG_NO_INDEX = hostile.strip_index(BAG)
BOMB = hostile.bz2_of_zeros(8)


def _read_all(path: Path) -> None:
    try:
        src = open_source(path)
    except SourceError as err:
        assert len(str(err)) < 2000
        return
    frames = list(src)
    for f in frames:
        assert f.ok or isinstance(f.error.reason, Reason), f
        if f.ok:
            assert max(f.image.shape[:2]) <= MAX_SIDE


@given(base=st.sampled_from(["indexed", "no_index"]),
       edits=st.lists(st.tuples(st.integers(0, 1 << 14), st.integers(0, 255)), max_size=6),
       cut=st.integers(0, 1 << 12),
       chunk=st.none() | st.tuples(st.sampled_from(["none", "bz2", "lz4", "zstd"]),
                                   st.integers(0, (1 << 32) - 1),
                                   st.sampled_from(["bomb", "bytes"]), st.binary(max_size=64)))
def fuzz_bag(base, edits, cut, chunk):
    b = bytearray(BAG if base == "indexed" else BAG_NO_INDEX)
    for pos, val in edits:
        if pos < len(b):
            b[pos] = val
    if 0 < cut < len(b) - 13:
        del b[-cut:]
    if chunk is not None:
        compression, declared, kind, payload = chunk
        b += hostile.chunk_record(BOMB if kind == "bomb" else payload, compression, declared)
    path = _TMP / "fuzz.bag"
    path.write_bytes(bytes(b))
    _read_all(path)


# --------------------------------------------------------------------------- YAML documents
YAML_BASE = hostile.intrinsic_yaml()
TOKENS = ["&a ", "*a", "&b [*a, *a, *a, *a]", "<<: *a\n", "9" * 50, "9" * 5000, "1e999", "-.inf", ".nan", ": ",
          "\n", "- ", "[", "]", "{", "}", "'", '"', "!!python/object/apply:os.system ['true']", "!!binary aGk=",
          "image_width: 320\n", "? ", "\t", "#", "0x" + "f" * 40, "1:2:3:4:5", "~", "%YAML 1.1\n---\n",
          "[" * 3000, "{a: " * 3000, "]" * 3000]


@given(inserts=st.lists(st.tuples(st.integers(0, len(YAML_BASE)), st.sampled_from(TOKENS) | st.text(max_size=8)),
                        max_size=6))
def fuzz_yaml_edits(inserts):
    text = YAML_BASE
    for pos, tok in sorted(inserts, reverse=True):
        text = text[:pos] + tok + text[pos:]
    _load(text)


@given(levels=st.integers(1, 14), fanout=st.integers(1, 12), field=st.sampled_from(["camera_matrix", "image_width"]))
def fuzz_yaml_aliases(levels, fanout, field):
    lines = ["l0: &l0 [1.0, 2.0]"]
    for i in range(1, levels):
        lines.append(f"l{i}: &l{i} [" + ", ".join([f"*l{i - 1}"] * fanout) + "]")
    _load(YAML_BASE + "\n".join(lines) + f"\nx_{field}: *l{levels - 1}\n")


def _load(text: str) -> None:
    path = _TMP / "fuzz.yaml"
    path.write_bytes(text.encode("utf-8", "replace"))
    try:
        calib_files.load_intrinsics(path)
    except CalibrationFileError as err:
        assert len(str(err)) < 1200, len(str(err))


def main() -> int:
    t0 = time.monotonic()
    for name, test, n in (("images", fuzz_image, 600), ("bags", fuzz_bag, 250),
                          ("yaml edits", fuzz_yaml_edits, 300), ("yaml aliases", fuzz_yaml_aliases, 60)):
        t = time.monotonic()
        settings(FUZZ, max_examples=n)(test)()
        print(f"fuzz {name}: {n} examples in {time.monotonic() - t:.1f} s", flush=True)
    print(f"fuzz: images ok, bags ok, yaml ok ({time.monotonic() - t0:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
