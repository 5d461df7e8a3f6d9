"""The hostile-input corpus (issue 8): every reproduction, through the `dtscal` command.

Each case runs `dtscal` in a subprocess whose address space is capped at 1 GB
(``hostile.run_capped``: the cap is asserted, and so is the absence of any traceback), so a
regression that allocates without bound fails here instead of taking the machine down.
A bad frame must be counted under its reason and skipped; a bad source or calibration
file must end the run with exit code 2 and a message that names it.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
import hostile  # noqa: E402
from ci import missing  # noqa: E402

from dtscal_lib import datasets  # noqa: E402

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="RLIMIT_AS and FIFOs as on Linux")

#: good intrinsic frames used around the hostile ones (enough for a stills calibration)
N_GOOD = 10


@pytest.fixture(scope="module")
def good_jpegs() -> list[bytes]:
    """JPEG payloads of the bundled recording in which the whole board is sharp and in view."""
    try:
        truth = datasets.load_truth()
    except Exception as exc:  # noqa: BLE001
        from ci import in_ci

        if in_ci():
            pytest.fail(f"the bundled session is missing under CI: {exc}")
        pytest.skip(f"bundled session missing: {exc}")
    ok = [f["index"] for f in truth["intrinsics"]["frames"]
          if f["board_visible"] and f["corners"] is not None and f["blur_px"] < 0.5]
    pick = set(ok[:: max(1, len(ok) // N_GOOD)][:N_GOOD])
    bag = datasets.session_dir() / datasets.INTRINSICS_BAG
    return [d for i, _s, d in datasets.read_bag_jpegs(bag) if i in pick]


def _folder(tmp: Path, good: list[bytes], extra: dict[str, bytes]) -> Path:
    folder = tmp / "frames"
    folder.mkdir()
    for i, data in enumerate(good):
        (folder / f"frame_{i + 1:03d}.jpg").write_bytes(data)
    for name, data in extra.items():
        (folder / name).write_bytes(data)
    return folder


def _intrinsics_json(*args) -> tuple[dict, str]:
    proc = hostile.run_capped(["calibrate-intrinsics", *args, "--no-write", "--json", "-q", "--robot", "hostbot"])
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout), proc.stderr


def _refused(*args, expect: str, timeout: float = 120) -> str:
    proc = hostile.run_capped(list(args), timeout=timeout)
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-3000:])
    message = proc.stderr.split("dtscal: error:", 1)[-1]
    assert expect in message, message
    assert len(message) < 2000, f"message of {len(message)} characters"
    return message


# --------------------------------------------------------------------------- the cap itself
def test_the_address_space_cap_is_in_force(tmp_path):
    script = tmp_path / "alloc.py"
    script.write_text("try:\n    b = bytearray(3 << 30)\nexcept MemoryError:\n    print('refused')\n"
                      "else:\n    print('allocated', len(b))\n")
    proc = hostile.run_capped([], script=str(script), timeout=60)
    assert proc.stdout.strip() == "refused"


# --------------------------------------------------------------------------- frames in a folder
@pytest.mark.slow
def test_hostile_frames_in_a_folder_are_counted_and_skipped(tmp_path, good_jpegs):
    jpeg = good_jpegs[0]
    bmp = hostile.encode(".bmp")
    fifo_name = "frame_050.png"
    extra = {
        "frame_040.jpg": hostile.jpeg_claiming(jpeg, 40000, 40000),   # SOF claims 40000 x 40000
        "frame_041.jpg": hostile.jpeg_claiming(jpeg, 30000, 30000),   # the 47 KB JPEG claiming 30000^2
        "frame_042.png": hostile.png_claiming(40000, 40000, rows_of_zeros=4),
        "frame_043.png": hostile.png_claiming(30000, 30000, rows_of_zeros=4),
        "frame_044.ppm": hostile.ppm_39_bytes(),
        "frame_045.ppm": hostile.ppm_short(),
        **{f"frame_06{i}.bmp": hostile.mutate(bmp, seed, 3, 64) for i, seed in enumerate(range(8))},
    }
    folder = _folder(tmp_path, good_jpegs, extra)
    os.mkfifo(folder / fifo_name)
    os.symlink("/dev/zero", folder / "frame_051.png")
    doc, _ = _intrinsics_json("--source", folder)
    frames = doc["frames"]
    rejected = frames["rejected"]
    assert frames["total"] == len(good_jpegs) + len(extra) + 2
    assert rejected.get("too_large", 0) >= 5, rejected
    assert rejected.get("not_a_file") == 2, rejected
    assert frames["used"] + rejected.get("outlier_view", 0) >= len(good_jpegs) - 1
    assert doc["image_size"] == [640, 480]


@pytest.mark.slow
def test_a_thumbnail_sorted_first_does_not_set_the_frame_size(tmp_path, good_jpegs):
    thumb = cv2.imencode(".png", np.full((1, 1, 3), 128, np.uint8))[1].tobytes()
    folder = _folder(tmp_path, good_jpegs, {"000_thumbnail.png": thumb})
    doc, _ = _intrinsics_json("--source", folder)
    assert doc["frames"]["rejected"].get("size_mismatch") == 1
    assert doc["frames"]["used"] + doc["frames"]["rejected"].get("outlier_view", 0) == len(good_jpegs)
    assert doc["image_size"] == [640, 480]


def test_a_requested_image_size_that_no_frame_has_is_refused_with_the_sizes_seen(tmp_path, good_jpegs):
    thumb = cv2.imencode(".png", np.full((1, 1, 3), 128, np.uint8))[1].tobytes()
    folder = _folder(tmp_path, good_jpegs[:2], {"000_thumbnail.png": thumb})
    message = _refused("calibrate-intrinsics", "--source", folder, "--image-size", "320x240", "--robot", "x",
                       "--no-write", "-q", expect="no frame has the requested image size 320x240")
    assert "640x480" in message and "1x1" in message


# --------------------------------------------------------------------------- bags
@pytest.mark.slow
def test_hostile_frames_in_a_bag_are_counted_and_skipped(tmp_path, good_jpegs):
    jpegs = list(good_jpegs)
    jpegs.insert(3, hostile.jpeg_claiming(good_jpegs[0], 40000, 40000))
    jpegs.insert(5, hostile.png_claiming(40000, 40000, rows_of_zeros=4))
    jpegs.insert(7, hostile.ppm_39_bytes())
    bag = hostile.write_bag(tmp_path / "hostile.bag", jpegs)
    doc, _ = _intrinsics_json("--source", bag)
    assert doc["frames"]["total"] == len(jpegs)
    assert doc["frames"]["rejected"]["too_large"] == 3


def _bag_without_index(tmp_path: Path, good: list[bytes], chunk: bytes) -> Path:
    bag = hostile.write_bag(tmp_path / "good.bag", good)
    path = tmp_path / "bomb.bag"
    path.write_bytes(hostile.strip_index(bag.read_bytes()) + chunk)
    return path


@pytest.mark.parametrize("declared", [0xFFFFFFFF, 1000])
def test_a_bz2_chunk_bomb_in_a_bag_without_index_is_refused_within_the_cap(tmp_path, good_jpegs, declared):
    # 64 MiB of zeros in a few hundred bytes of bz2: it declares 4 GB (refused unread) or 1000 bytes (a lie,
    # found after at most 1001 bytes of output). Either way the frames before it count, then the bomb.
    chunk = hostile.chunk_record(hostile.bz2_of_zeros(64), "bz2", declared)
    bag = _bag_without_index(tmp_path, good_jpegs[:3], chunk)
    script = tmp_path / "walk.py"
    script.write_text(
        "import sys, collections\nfrom dtscal_lib.sources import open_source\n"
        "frames = list(open_source(sys.argv[1]))\n"
        "print(sum(f.ok for f in frames), [(f.error.reason.value, str(f.error)) for f in frames if f.error])\n")
    proc = hostile.run_capped([bag], script=str(script), timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    n_ok, errors = proc.stdout.split(" ", 1)
    assert int(n_ok) == 3
    reason = "too_large" if declared > 1 << 27 else "unreadable"
    assert errors.count(f"('{reason}'") == 1, errors
    assert "declares" in errors if declared > 1 << 27 else "more than its declared" in errors


def test_an_index_that_counts_more_messages_than_the_file_holds_is_not_believed(tmp_path, good_jpegs):
    # found by hostile_fuzz.py: an indexed bag cut by one byte, an uncompressed chunk record appended; rosbags then
    # reads a message count of 687,865,859 from the damaged index, and list(source) preallocated for it (MemoryError)
    bag = hostile.write_bag(tmp_path / "base.bag", good_jpegs[:3]).read_bytes()[:-1]
    path = tmp_path / "damaged.bag"
    path.write_bytes(bag + hostile.chunk_record(hostile.bz2_of_zeros(8), "none", 0))
    script = tmp_path / "walk.py"
    script.write_text("import sys\nfrom dtscal_lib.sources import open_source\nsrc = open_source(sys.argv[1])\n"
                      "frames = list(src)\nprint(len(src), sum(f.ok for f in frames))\n")
    proc = hostile.run_capped([path], script=str(script), timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.split() == ["4", "3"]  # the three frames, then the damaged end


def test_a_bag_that_is_only_a_chunk_bomb_is_refused_with_a_message(tmp_path):
    header = hostile._record({"op": b"\x03", "index_pos": (0).to_bytes(8, "little"),
                              "conn_count": bytes(4), "chunk_count": bytes(4)}, b" " * 4000)
    path = tmp_path / "bomb_only.bag"
    path.write_bytes(b"#ROSBAG V2.0\n" + header
                     + hostile.chunk_record(hostile.bz2_of_zeros(16), "bz2", 0xFFFFFFFF))
    assert path.stat().st_size < 6600
    message = _refused("calibrate-intrinsics", "--source", path, "--robot", "x", "--no-write", "-q",
                       expect="bomb_only.bag holds more data than the kit reads at once")
    assert "beyond the limit of 128 MiB" in message


# --------------------------------------------------------------------------- special files as sources
def test_a_fifo_as_source_is_refused_not_waited_on(tmp_path):
    fifo = tmp_path / "camera.bag"
    os.mkfifo(fifo)
    _refused("calibrate-intrinsics", "--source", fifo, "--robot", "x", "--no-write", "-q", expect="FIFO", timeout=60)


@pytest.mark.parametrize("name", ["zero.bag", "zero.png", "zero.mp4", "zero"])
def test_a_symlink_to_dev_zero_as_source_is_refused(tmp_path, name):
    link = tmp_path / name
    os.symlink("/dev/zero", link)
    _refused("calibrate-intrinsics", "--source", link, "--robot", "x", "--no-write", "-q",
             expect="character device", timeout=60)


# --------------------------------------------------------------------------- video
def _video(tmp_path: Path, good: list[bytes], n: int = 41) -> Path:
    path = tmp_path / "sweep.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 15, (640, 480))
    if not writer.isOpened():
        missing("this OpenCV build cannot write MJPG AVI")  # a failure under CI, a skip elsewhere
    images = [cv2.imdecode(np.frombuffer(d, np.uint8), cv2.IMREAD_COLOR) for d in good]
    for i in range(n):
        writer.write(images[i % len(images)])
    writer.release()
    return path


def test_a_video_with_flipped_bytes_accounts_for_every_frame(tmp_path, good_jpegs):
    path = _video(tmp_path, good_jpegs)
    bad = tmp_path / "flipped.avi"
    bad.write_bytes(hostile.flip_bytes(path.read_bytes(), 200, seed=0))
    script = tmp_path / "walk.py"
    script.write_text(
        "import sys\nfrom dtscal_lib.sources import open_source\n"
        "frames = list(open_source(sys.argv[1]))\n"
        "print(len(frames), sum(f.ok for f in frames))\n"
        "for f in frames:\n    if f.error: print(f.error.reason.value, f.error)\n")
    proc = hostile.run_capped([bad], script=str(script), timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = proc.stdout.splitlines()
    total, ok = map(int, lines[0].split())
    # before the fix the reader stopped silently at the first undecodable frame (frame 9 of 41 in the issue)
    assert total == 41, proc.stdout
    assert len(lines) > 1, "these 200 flipped bytes (seed 0) break at least one frame"
    assert all(line.startswith("video_decode_failed video flipped.avi") for line in lines[1:]), lines
    assert ok == 41 - (len(lines) - 1)


def test_a_video_cut_short_says_how_far_it_got(tmp_path, good_jpegs):
    path = _video(tmp_path, good_jpegs)
    data = path.read_bytes()
    cut = tmp_path / "cut.avi"
    cut.write_bytes(data[: len(data) // 2])
    script = tmp_path / "walk.py"
    script.write_text(
        "import sys\nfrom dtscal_lib.sources import open_source\n"
        "frames = list(open_source(sys.argv[1]))\n"
        "print(len(frames), sum(f.ok for f in frames))\n"
        "for f in frames:\n    if f.error: print(f.error.reason.value, f.error)\n")
    proc = hostile.run_capped([cut], script=str(script), timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = proc.stdout.splitlines()
    total, ok = map(int, lines[0].split())
    # the container still states 41 frames: the end is said, with how far the reading got, not silent
    assert 0 < ok < 41 and total == ok + 1, proc.stdout
    assert lines[1].startswith(f"video_decode_failed video cut.avi stops decoding at frame {ok} of the 41"), lines
    assert f"{ok} frames were read, {41 - ok} are lost" in lines[1]


# --------------------------------------------------------------------------- extrinsics
@pytest.mark.slow
def test_hostile_frames_in_extrinsics_have_their_own_reasons(tmp_path):
    from dtscal_lib import calib_files

    calib_files.write_defaults(tmp_path / "cal")
    intr = tmp_path / "cal" / "camera_intrinsic" / "default.yaml"
    ext = [d for _i, _s, d in datasets.read_bag_jpegs(datasets.session_dir() / datasets.EXTRINSICS_BAG)][:1]
    square = cv2.imencode(".png", np.full((300, 300, 3), 90, np.uint8))[1].tobytes()
    folder = tmp_path / "ext"
    folder.mkdir()
    (folder / "a_bomb.jpg").write_bytes(hostile.jpeg_claiming(ext[0], 40000, 40000))
    (folder / "b_square.png").write_bytes(square)
    (folder / "c_board.jpg").write_bytes(ext[0])
    proc = hostile.run_capped(["calibrate-extrinsics", "--source", folder, "--intrinsics", intr, "--no-write",
                               "--json", "-q", "--robot", "hostbot"])
    assert proc.returncode == 0, proc.stderr[-3000:]
    rejected = json.loads(proc.stdout)["frames"]["rejected"]
    assert rejected == {"size_mismatch": 1, "too_large": 1}, rejected


# --------------------------------------------------------------------------- calibration YAML
def _extrinsics_with(tmp_path: Path, text: str, expect: str) -> str:
    path = tmp_path / "hostbot.yaml"
    path.write_text(text)
    bag = datasets.session_dir() / datasets.EXTRINSICS_BAG
    message = _refused("calibrate-extrinsics", "--source", bag, "--intrinsics", path, "--no-write", "-q",
                       expect=expect, timeout=60)
    assert str(path) in message
    return message


def test_a_yaml_alias_bomb_as_intrinsics_is_refused_fast(tmp_path):
    text = hostile.yaml_alias_bomb(9)
    assert len(text) < 1024
    _extrinsics_with(tmp_path, text, "alias bomb")


@pytest.mark.parametrize("digits", [400, 5000])
def test_a_huge_integer_in_a_field_is_refused_by_name(tmp_path, digits):
    text = hostile.intrinsic_yaml().replace("image_width: 640", "image_width: " + "9" * digits)
    message = _extrinsics_with(tmp_path, text, "image_width")
    assert f"{digits} digits" in message


def test_a_huge_integer_in_a_matrix_is_refused_by_name(tmp_path):
    text = hostile.intrinsic_yaml().replace("rows: 3", "rows: " + "7" * 400, 1)
    _extrinsics_with(tmp_path, text, "camera_matrix.rows")


@pytest.mark.parametrize("nest", ["[" * 5000 + "]" * 5000, "{a: " * 5000 + "1" + "}" * 5000])
def test_deep_nesting_is_refused_without_recursion_error(tmp_path, nest):
    _extrinsics_with(tmp_path, hostile.intrinsic_yaml() + f"extra: {nest}\n", "nests more than")


def test_duplicate_keys_are_refused(tmp_path):
    text = hostile.intrinsic_yaml() + "image_width: 320\n"
    _extrinsics_with(tmp_path, text, "'image_width' appears twice")


def test_an_oversized_yaml_file_is_refused_unparsed(tmp_path):
    text = hostile.intrinsic_yaml() + "# padding\n" * 20000
    _extrinsics_with(tmp_path, text, "a calibration file is a few KB")


def test_a_fifo_as_intrinsics_is_refused(tmp_path):
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    bag = datasets.session_dir() / datasets.EXTRINSICS_BAG
    _refused("calibrate-extrinsics", "--source", bag, "--intrinsics", fifo, "--no-write", "-q",
             expect="not a regular file", timeout=60)


# --------------------------------------------------------------------------- fuzzing
def test_fuzz_image_headers_bag_records_and_yaml_documents_under_the_cap():
    """hostile_fuzz.py: hypothesis over the three parsers, in one capped subprocess, derandomized."""
    script = Path(__file__).parent / "hostile_fuzz.py"
    proc = hostile.run_capped([], script=str(script), timeout=110)
    assert proc.returncode == 0, (proc.stdout[-3000:], proc.stderr[-3000:])
    assert "fuzz: images ok, bags ok, yaml ok" in proc.stdout, proc.stdout


# --------------------------------------------------------------------------- limits checked before reading
def test_a_huge_frame_file_is_refused_by_its_size_before_it_is_read(tmp_path):
    """A 257 MiB file (sparse: it costs no disk) is refused from fstat's size, never read into memory: the
    message gives its size (a file read first and measured after would say it "grew beyond" the limit)."""
    from dtscal_lib.errors import FrameError
    from dtscal_lib.sources.decode import MAX_FILE_BYTES, read_image_file

    big = tmp_path / "huge.jpg"
    with open(big, "wb") as f:
        f.truncate(MAX_FILE_BYTES + (1 << 20))
    with pytest.raises(FrameError) as e:
        read_image_file(big)
    assert e.value.reason == "too_large" and f"has {MAX_FILE_BYTES + (1 << 20)} bytes" in str(e.value), str(e.value)


def test_a_bag_record_declaring_a_2_gib_header_is_damage_not_a_cut_file(tmp_path):
    """The first record of a bag claims a 2 GiB header: the walk stops there as damaged (the header length is
    checked before anything is read), not as a file cut short after trying to read 2 GiB."""
    import struct

    from dtscal_lib.sources.bagformat import ScanEnd, scan_bag
    from live_fakes import write_test_bag

    raw = bytearray(Path(write_test_bag(tmp_path / "r.bag", 3)).read_bytes())
    assert raw[:13] == b"#ROSBAG V2.0\n"
    raw[13:17] = struct.pack("<I", 1 << 31)
    bad = tmp_path / "bad.bag"
    bad.write_bytes(raw)
    end = [x for x in scan_bag(bad) if isinstance(x, ScanEnd)]
    assert len(end) == 1 and end[0].status == "damaged" and end[0].offset == 13, end
    assert "record header length 2147483648" in end[0].detail, end
