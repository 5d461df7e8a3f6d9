"""Builders of damaged and hostile input for tests/test_hostile_input.py and tests/hostile_fuzz.py.

Each builder makes, in a few milliseconds and a few kilobytes, a file that once made the kit
allocate gigabytes, hang or print a traceback (issue 8), plus the capped runner that every
hostile input goes through: a subprocess whose address space is limited with
``resource.setrlimit(RLIMIT_AS)``, so that unbounded memory fails the test instead of the machine.
"""

from __future__ import annotations

import bz2
import os
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import cv2
import numpy as np

#: address-space cap of every hostile run
CAP_BYTES = 1 << 30
#: printed by the capped runner once the cap is in force (tests assert it)
CAP_BANNER = "[address-space cap in force: {} bytes]"

_RUNNER = """
import resource, runpy, sys
cap = int(sys.argv[1])
resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
soft, hard = resource.getrlimit(resource.RLIMIT_AS)
assert soft == cap and hard == cap, (soft, hard)
sys.stderr.write("[address-space cap in force: %d bytes]\\n" % soft)
sys.stderr.flush()
import cv2
cv2.setNumThreads(1)  # a many-core machine must not spend the cap on per-thread stacks and arenas
if sys.argv[2] == "--script":
    sys.argv = sys.argv[3:]
    runpy.run_path(sys.argv[0], run_name="__main__")
else:
    from dtscal_lib.cli import main
    sys.exit(main(sys.argv[2:]))
"""


def run_capped(args, *, timeout: float = 300, cwd=None, script: str | None = None) -> subprocess.CompletedProcess:
    """Run ``dtscal ARGS`` (or ``python SCRIPT ARGS``) under the address-space cap.

    Asserts that the cap was in force and that nothing printed a Python traceback.
    """
    cmd = [sys.executable, "-c", _RUNNER, str(CAP_BYTES)]
    cmd += ["--script", script, *map(str, args)] if script else [*map(str, args)]
    env = dict(os.environ, MALLOC_ARENA_MAX="2", OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=cwd, env=env)
    assert CAP_BANNER.format(CAP_BYTES) in proc.stderr, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr and "Traceback" not in proc.stdout, proc.stderr[-4000:]
    return proc


# --------------------------------------------------------------------------- images
def small_image(w: int = 16, h: int = 12) -> np.ndarray:
    rng = np.random.default_rng(8)
    return rng.integers(0, 255, (h, w, 3), dtype=np.uint8)


def encode(ext: str, img: np.ndarray | None = None) -> bytes:
    ok, buf = cv2.imencode(ext, small_image() if img is None else img)
    assert ok
    return buf.tobytes()


def jpeg_sof_offset(jpeg: bytes) -> int:
    """Byte offset of the SOF marker (FF Cn) of a JPEG."""
    pos = 2
    while True:
        marker = jpeg[pos + 1]
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            return pos
        pos += 2 + struct.unpack(">H", jpeg[pos + 2:pos + 4])[0]


def jpeg_claiming(jpeg: bytes, width: int, height: int) -> bytes:
    """The same JPEG with a frame header (SOF) that claims ``width`` x ``height``."""
    at = jpeg_sof_offset(jpeg)
    b = bytearray(jpeg)
    b[at + 5:at + 9] = struct.pack(">HH", height, width)
    return bytes(b)


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def png_claiming(width: int, height: int, rows_of_zeros: int = 0) -> bytes:
    """A valid-looking greyscale PNG of ``width`` x ``height`` (CRCs right).

    ``rows_of_zeros`` rows of real zlib data follow (all of them makes the 875 KB PNG of
    30000 x 30000 of the issue; a few are enough to reach the decoder).
    """
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    comp = zlib.compressobj(9)
    row = bytes(width + 1)
    idat = b"".join(comp.compress(row) for _ in range(rows_of_zeros)) + comp.flush()
    return b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", ihdr) + _png_chunk(b"IDAT", idat) + _png_chunk(b"IEND", b"")


def ppm_39_bytes() -> bytes:
    """The issue's 39-byte PPM: a header claiming 40000 x 40000, and almost no data."""
    head = b"P6\n40000 40000\n255\n"
    return head + bytes(39 - len(head))


def ppm_short() -> bytes:
    """A 39-byte PPM whose small size is honest but whose pixels are missing."""
    head = b"P6\n8 8\n255\n"
    return head + bytes(39 - len(head))


def mutate(data: bytes, seed: int, n: int = 4, region: int | None = None) -> bytes:
    """``data`` with ``n`` random bytes replaced (within the first ``region`` bytes, if given)."""
    rng = np.random.default_rng(seed)
    b = bytearray(data)
    span = min(len(b), region or len(b))
    for pos in rng.integers(0, span, n):
        b[int(pos)] = int(rng.integers(0, 256))
    return bytes(b)


def flip_bytes(data: bytes, n: int, seed: int) -> bytes:
    """``data`` with ``n`` bytes inverted at random places."""
    rng = np.random.default_rng(seed)
    b = bytearray(data)
    for pos in rng.integers(0, len(b), n):
        b[int(pos)] ^= 0xFF
    return bytes(b)


# --------------------------------------------------------------------------- bags
def _field(name: str, value: bytes) -> bytes:
    f = name.encode() + b"=" + value
    return struct.pack("<I", len(f)) + f


def _record(fields: dict[str, bytes], data: bytes) -> bytes:
    header = b"".join(_field(k, v) for k, v in fields.items())
    return struct.pack("<I", len(header)) + header + struct.pack("<I", len(data)) + data


def chunk_record(payload: bytes, compression: str, declared_size: int) -> bytes:
    """A bag chunk record (op 0x05) with the given compressed payload and declared uncompressed size."""
    return _record({"op": b"\x05", "compression": compression.encode(), "size": struct.pack("<I", declared_size)},
                   payload)


def bz2_of_zeros(mib: int) -> bytes:
    """bz2 of ``mib`` MiB of zeros (16 MiB compress to about 50 bytes)."""
    c = bz2.BZ2Compressor(9)
    block = bytes(1 << 20)
    return b"".join(c.compress(block) for _ in range(mib)) + c.flush()


def strip_index(bag: bytes) -> bytes:
    """A bag cut just before its index, as a killed recording leaves it."""
    # the bag header record follows the 13-byte magic; its index_pos field says where the index starts
    hlen = struct.unpack_from("<I", bag, 13)[0]
    header = bag[17:17 + hlen]
    at = header.find(b"index_pos=")
    index_pos = struct.unpack_from("<Q", header, at + len(b"index_pos="))[0]
    return bag[:index_pos]


def write_bag(path: Path, jpegs: list[bytes], topic: str = "/hostbot/camera_node/image/compressed") -> Path:
    from dtscal_lib.sources import write_compressed_image_bag

    return write_compressed_image_bag(path, topic, [(10**9 + i * 10**8, d) for i, d in enumerate(jpegs)])


# --------------------------------------------------------------------------- YAML
def yaml_alias_bomb(levels: int = 9) -> str:
    """The billion-laughs document: under 1 KB, ``9 ** levels`` values when expanded."""
    lines = ['l0: &l0 ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    for i in range(1, levels):
        lines.append(f"l{i}: &l{i} [" + ",".join([f"*l{i - 1}"] * 9) + "]")
    lines.append(f"camera_matrix: *l{levels - 1}")
    return "\n".join(lines) + "\n"


def intrinsic_yaml() -> str:
    """A valid camera_intrinsic YAML (the Duckietown default)."""
    import yaml

    from dtscal_lib import duckietown as dt

    return yaml.safe_dump(dt.DEFAULT_INTRINSICS, sort_keys=False, default_flow_style=None)
