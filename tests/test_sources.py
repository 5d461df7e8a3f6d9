"""Camera sources: bags, videos, folders, globs, and the damage they survive."""

from __future__ import annotations

import struct
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dtscal_lib.errors import FrameError, SourceError
from dtscal_lib.sources import (
    Frame,
    decode_image,
    list_image_topics,
    open_source,
    write_compressed_image_bag,
)
from dtscal_lib.sources.bagformat import RawMessage, ScanEnd, scan_bag
from dtscal_lib.sources.decode import jpeg_scan_problem, raw_image_to_bgr

TOPIC = "/autobot01/camera_node/image/compressed"


def picture(i: int, size=(640, 480)) -> np.ndarray:
    """A distinct BGR test picture per index (textured, so JPEGs have real scan data)."""
    w, h = size
    img = np.zeros((h, w, 3), np.uint8)
    img[:] = (20 + 7 * i % 200, 90, 200 - 5 * i % 150)
    cv2.circle(img, (50 + 13 * i % (w - 100), h // 2), 40, (255, 255, 255), -1)
    cv2.putText(img, f"frame {i}", (20, 60), cv2.FONT_HERSHEY_SIMPLEX, 1.5, (0, 0, 0), 3)
    return img


def jpeg(img: np.ndarray, quality: int = 90) -> bytes:
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, quality])
    assert ok
    return buf.tobytes()


def decoded(b: bytes) -> np.ndarray:
    return cv2.imdecode(np.frombuffer(b, np.uint8), cv2.IMREAD_COLOR)


@pytest.fixture(scope="module")
def jpegs() -> list[bytes]:
    return [jpeg(picture(i)) for i in range(24)]


def stamps_ns(n: int, start_s: int = 1_700_000_000) -> list[int]:
    return [start_s * 10**9 + i * 33_333_333 for i in range(n)]


@pytest.fixture()
def good_bag(tmp_path, jpegs) -> Path:
    # small chunks, so cutting the file leaves several whole chunks before the cut
    return write_compressed_image_bag(tmp_path / "intrinsics.bag", TOPIC, zip(stamps_ns(len(jpegs)), jpegs),
                                      frame_id="camera", chunk_threshold=60_000)


# ---------------------------------------------------------------------------- decode_image


def test_decode_image_matches_opencv(jpegs):
    img = decode_image(jpegs[3])
    assert img.dtype == np.uint8 and img.shape == (480, 640, 3)
    np.testing.assert_array_equal(img, decoded(jpegs[3]))
    # numpy buffers and memoryviews are accepted too
    np.testing.assert_array_equal(decode_image(np.frombuffer(jpegs[3], np.uint8)), img)
    np.testing.assert_array_equal(decode_image(memoryview(jpegs[3])), img)


def test_decode_image_grey_png_becomes_bgr():
    grey = (np.arange(12 * 16).reshape(12, 16) % 256).astype(np.uint8)
    ok, buf = cv2.imencode(".png", grey)
    img = decode_image(buf.tobytes())
    assert img.shape == (12, 16, 3)
    for c in range(3):
        np.testing.assert_array_equal(img[:, :, c], grey)


def test_decode_image_empty():
    with pytest.raises(FrameError) as e:
        decode_image(b"")
    assert e.value.reason == "empty"


@pytest.mark.parametrize("keep", [0.95, 0.6, 0.2, 0.01])
def test_decode_image_truncated_jpeg_is_flagged(jpegs, keep):
    data = jpegs[0][: int(len(jpegs[0]) * keep)]
    # OpenCV itself would hand back a partly grey picture for most of these cuts
    with pytest.raises(FrameError) as e:
        decode_image(data)
    assert e.value.reason == "corrupt_jpeg"
    assert "end-of-image" in str(e.value)


def test_decode_image_tolerates_padding_after_end_marker(jpegs):
    np.testing.assert_array_equal(decode_image(jpegs[1] + b"\x00\x00\n"), decoded(jpegs[1]))


def test_decode_image_stray_marker_in_scan_data(jpegs):
    data = bytearray(jpegs[2])
    assert jpeg_scan_problem(bytes(data)) is None
    # put a marker (FF C0) in the middle of the entropy-coded data
    mid = len(data) // 2
    data[mid : mid + 2] = b"\xff\xc0"
    problem = jpeg_scan_problem(bytes(data))
    assert problem is not None and "stray marker" in problem
    with pytest.raises(FrameError) as e:
        decode_image(bytes(data))
    assert e.value.reason == "corrupt_jpeg"


@pytest.mark.parametrize("params", [
    [cv2.IMWRITE_JPEG_QUALITY, 100],
    [cv2.IMWRITE_JPEG_QUALITY, 40, cv2.IMWRITE_JPEG_RST_INTERVAL, 3],
    [cv2.IMWRITE_JPEG_PROGRESSIVE, 1],
    [cv2.IMWRITE_JPEG_OPTIMIZE, 1],
])
def test_valid_jpeg_variants_are_not_flagged(params):
    rng = np.random.default_rng(5)
    img = rng.integers(0, 256, (64, 96, 3), np.uint8)
    ok, buf = cv2.imencode(".jpg", img, params)
    b = buf.tobytes()
    assert jpeg_scan_problem(b) is None
    np.testing.assert_array_equal(decode_image(b), decoded(b))


def test_decode_image_garbage_and_damaged_png():
    with pytest.raises(FrameError) as e:
        decode_image(b"hello, this is text")
    assert e.value.reason == "not_an_image"
    ok, buf = cv2.imencode(".png", picture(0, (32, 24)))
    png = buf.tobytes()
    with pytest.raises(FrameError) as e:
        decode_image(png[:40])
    assert e.value.reason == "corrupt_image"


def test_raw_image_encodings():
    bgr = picture(4, (20, 10))
    rgb = bgr[:, :, ::-1].copy()
    np.testing.assert_array_equal(raw_image_to_bgr(10, 20, "rgb8", 60, rgb.tobytes()), bgr)
    np.testing.assert_array_equal(raw_image_to_bgr(10, 20, "bgr8", 60, bgr.tobytes()), bgr)
    # padded rows (step > width * channels)
    padded = np.zeros((10, 64), np.uint8)
    padded[:, :60] = bgr.reshape(10, 60)
    np.testing.assert_array_equal(raw_image_to_bgr(10, 20, "bgr8", 64, padded.tobytes()), bgr)
    grey = bgr[:, :, 1].copy()
    out = raw_image_to_bgr(10, 20, "mono8", 20, grey.tobytes())
    assert out.shape == (10, 20, 3) and np.array_equal(out[:, :, 2], grey)
    with pytest.raises(FrameError) as e:
        raw_image_to_bgr(10, 20, "bayer_rggb8", 20, grey.tobytes())
    assert e.value.reason == "unsupported_encoding" and "image/compressed" in str(e.value)
    with pytest.raises(FrameError) as e:
        raw_image_to_bgr(10, 20, "bgr8", 60, bgr.tobytes()[:100])
    assert e.value.reason == "truncated"


# ---------------------------------------------------------------------------- folders and globs


@pytest.fixture()
def image_folder(tmp_path) -> Path:
    d = tmp_path / "frames"
    d.mkdir()
    for i in (1, 2, 10):  # natural order must put img_10 last
        ok, buf = cv2.imencode(".png", picture(i, (64, 48)))
        (d / f"img_{i}.png").write_bytes(buf.tobytes())
    (d / "img_3.jpg").write_bytes(jpeg(picture(3, (64, 48))))
    (d / "README.txt").write_text("frames of the calibration session\n")
    (d / "img_4.jpg").write_bytes(b"")  # zero bytes
    (d / ".DS_Store").write_bytes(b"\x00\x00\x00\x01Bud1")  # hidden: ignored
    (d / "sub").mkdir()  # sub-folder: ignored
    return d


def test_folder_source(image_folder):
    src = open_source(image_folder)
    assert src.kind == "folder" and src.is_stream is False and src.topic is None
    assert len(src) == 6
    frames = list(src)
    assert [f.name for f in frames] == ["img_1.png", "img_2.png", "img_3.jpg", "img_4.jpg", "img_10.png", "README.txt"]
    assert [f.index for f in frames] == list(range(6))
    assert all(isinstance(f, Frame) for f in frames)
    reasons = {f.name: (f.error.reason if f.error else None) for f in frames}
    assert reasons == {"img_1.png": None, "img_2.png": None, "img_3.jpg": None, "img_4.jpg": "empty",
                       "img_10.png": None, "README.txt": "not_an_image"}
    # PNG is lossless: pixels come back exactly
    np.testing.assert_array_equal(frames[4].image, picture(10, (64, 48)))
    assert frames[3].image is None and not frames[3].ok and frames[0].ok
    assert "img_4.jpg" in str(frames[3].error)
    assert "1 other files" in src.describe()
    # re-iterable
    assert [f.name for f in src] == [f.name for f in frames]


def test_folder_without_images(tmp_path):
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(SourceError, match="no image files"):
        open_source(tmp_path)


def test_glob_source(image_folder):
    src = open_source(str(image_folder / "img_*.png"))
    assert src.kind == "glob" and not src.is_stream
    assert [f.name for f in src] == ["img_1.png", "img_2.png", "img_10.png"]
    assert len(src) == 3
    with pytest.raises(SourceError, match="no file matches"):
        open_source(str(image_folder / "*.tiff"))


def test_single_image_file(image_folder):
    src = open_source(image_folder / "img_2.png")
    assert len(src) == 1 and [f.ok for f in src] == [True]


def test_topic_only_for_bags(image_folder):
    with pytest.raises(SourceError, match="only applies to ROS bags"):
        open_source(image_folder, topic=TOPIC)


# ---------------------------------------------------------------------------- video


def test_video_source(tmp_path):
    path = tmp_path / "drive.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30, (160, 120))
    assert writer.isOpened()
    for i in range(15):
        writer.write(picture(i, (160, 120)))
    writer.release()
    src = open_source(path)
    assert src.kind == "video" and src.is_stream
    frames = list(src)
    assert len(frames) == 15
    assert all(f.ok and f.image.shape == (120, 160, 3) and f.image.dtype == np.uint8 for f in frames)
    assert [f.index for f in frames] == list(range(15))
    np.testing.assert_allclose([f.stamp for f in frames], np.arange(15) / 30.0, atol=1e-9)
    assert frames[7].name == "drive.avi#7"
    # MJPG is lossy; the frame still looks like what was written
    assert np.abs(frames[7].image.astype(int) - picture(7, (160, 120))).mean() < 6
    with pytest.raises(TypeError, match="not known before reading"):
        len(src)
    assert src.estimated_frames == 15
    assert "30 fps" in src.describe()


def test_damaged_video(tmp_path):
    path = tmp_path / "broken.mp4"
    path.write_bytes(b"\x00\x00\x00\x18ftypmp42" + b"\x13" * 200)
    with pytest.raises(SourceError, match="cannot open the video"):
        open_source(path)


# ---------------------------------------------------------------------------- bags


def test_bag_round_trip(good_bag, jpegs):
    src = open_source(good_bag)
    assert src.kind == "bag" and src.is_stream and src.topic == TOPIC
    assert not src.truncated
    assert len(src) == len(jpegs)
    frames = list(src)
    assert len(frames) == len(jpegs)
    for i, (f, b) in enumerate(zip(frames, jpegs)):
        assert f.ok and f.index == i and f.name == f"intrinsics.bag#{i}"
        np.testing.assert_array_equal(f.image, decoded(b))
    np.testing.assert_allclose([f.stamp for f in frames], np.array(stamps_ns(len(jpegs))) * 1e-9, rtol=0, atol=1e-6)
    assert list_image_topics(good_bag) == [TOPIC]
    assert TOPIC in src.describe() and "24 frames" in src.describe()


def test_bag_bytes_and_header_are_stored_exactly(good_bag, jpegs):
    from rosbags.rosbag1 import Reader
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    with Reader(good_bag) as r:
        conn = r.connections[0]
        assert conn.msgtype == "sensor_msgs/msg/CompressedImage"
        assert conn.digest == "8f7a12909da2c9d3332d540a0977563f"  # ROS's md5 of sensor_msgs/CompressedImage
        for i, (_c, t, raw) in enumerate(r.messages()):
            msg = ts.deserialize_ros1(raw, "sensor_msgs/msg/CompressedImage")
            assert msg.format == "jpeg" and msg.header.frame_id == "camera" and msg.header.seq == i
            assert msg.data.tobytes() == jpegs[i]
            assert t == stamps_ns(len(jpegs))[i] == msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec


def test_bag_writer_replaces_atomically_and_validates(tmp_path, jpegs):
    path = tmp_path / "out" / "a.bag"
    write_compressed_image_bag(path, TOPIC, [(0, jpegs[0])])
    write_compressed_image_bag(path, TOPIC, [(0, jpegs[0]), (1, jpegs[1])])  # replaces
    assert len(open_source(path)) == 2
    with pytest.raises(SourceError, match="absolute ROS name"):
        write_compressed_image_bag(tmp_path / "b.bag", "camera/image", [(0, jpegs[0])])
    with pytest.raises(SourceError, match="must be bytes"):
        write_compressed_image_bag(tmp_path / "c.bag", TOPIC, [(0, jpegs[0]), (1, "not bytes")])
    with pytest.raises(SourceError, match="stamp_ns"):
        write_compressed_image_bag(tmp_path / "d.bag", TOPIC, [(-5, jpegs[0])])
    # failed writes leave nothing behind, not even the temporary file
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["a.bag"]


def test_bag_with_corrupt_and_empty_messages(tmp_path, jpegs):
    payloads = [jpegs[0], b"\x01\x02garbage", jpegs[1], jpegs[2][: len(jpegs[2]) // 2], b"", jpegs[3]]
    path = write_compressed_image_bag(tmp_path / "bad.bag", TOPIC, zip(stamps_ns(6), payloads))
    frames = list(open_source(path))
    assert len(frames) == 6
    reasons = [f.error.reason if f.error else None for f in frames]
    assert reasons == [None, "not_an_image", None, "corrupt_jpeg", "empty", None]
    np.testing.assert_array_equal(frames[5].image, decoded(jpegs[3]))
    assert all(isinstance(f.error, FrameError) for f in frames if f.error)
    assert frames[3].image is None


def _cut(src: Path, dst: Path, nbytes: int) -> Path:
    dst.write_bytes(src.read_bytes()[:nbytes])
    return dst


@pytest.mark.parametrize("keep", [0.9, 0.7, 0.5, 0.3])
def test_truncated_bag_yields_readable_frames_then_truncated(good_bag, jpegs, tmp_path, keep):
    size = good_bag.stat().st_size
    cut = _cut(good_bag, tmp_path / "cut.bag", int(size * keep))
    src = open_source(cut)
    assert src.truncated
    frames = list(src)
    assert len(frames) == len(src)
    *good, last = frames
    assert last.error is not None and last.error.reason == "truncated" and last.image is None
    msg = str(last.error)
    assert "truncated" in msg and f"read {len(good)} frames" in msg and "cut.bag" in msg
    # every frame before the cut is intact and in order; most of the recording survives
    assert len(good) >= int(len(jpegs) * keep) - 4
    for i, f in enumerate(good):
        assert f.ok and f.index == i
        np.testing.assert_array_equal(f.image, decoded(jpegs[i]))
    assert last.index == len(good)
    assert "cut" in src.describe() or "ends" in src.describe()
    assert list_image_topics(cut) == [TOPIC]


def _index_pos(path: Path) -> int:
    data = path.read_bytes()
    i = data.index(b"index_pos=") + len(b"index_pos=")
    return struct.unpack("<Q", data[i : i + 8])[0]


def test_bag_cut_exactly_before_its_index(good_bag, jpegs, tmp_path):
    cut = _cut(good_bag, tmp_path / "noindex.bag", _index_pos(good_bag))
    frames = list(open_source(cut))
    assert [f.ok for f in frames[:-1]] == [True] * len(jpegs)
    assert frames[-1].error.reason == "truncated"
    assert "rosbag reindex" in str(frames[-1].error)


def test_unindexed_recording(good_bag, jpegs, tmp_path):
    """A recording killed before it closed: header says index_pos = 0, no index at the end."""
    data = bytearray(good_bag.read_bytes()[: _index_pos(good_bag)])
    i = data.index(b"index_pos=") + len(b"index_pos=")
    data[i : i + 8] = struct.pack("<Q", 0)
    path = tmp_path / "killed.bag"
    path.write_bytes(bytes(data))
    src = open_source(path)
    frames = list(src)
    assert len(frames) == len(src) == len(jpegs) + 1
    assert all(f.ok for f in frames[:-1]) and frames[-1].error.reason == "truncated"


def test_bag_cut_inside_header_area(good_bag, tmp_path):
    cut = _cut(good_bag, tmp_path / "tiny.bag", 3000)  # inside the 4 KiB bag-header padding
    with pytest.raises(SourceError, match="cut short"):
        open_source(cut)
    with pytest.raises(SourceError, match="cut short after 5 bytes"):
        open_source(_cut(good_bag, tmp_path / "five.bag", 5))
    empty = _cut(good_bag, tmp_path / "empty.bag", 0)
    with pytest.raises(SourceError, match="empty"):
        open_source(empty)


@pytest.mark.parametrize("compression", ["bz2", "lz4"])
def test_truncated_compressed_bag(tmp_path, jpegs, compression):
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    CI, Hd, T = (ts.types[n] for n in ("sensor_msgs/msg/CompressedImage", "std_msgs/msg/Header",
                                        "builtin_interfaces/msg/Time"))
    path = tmp_path / f"{compression}.bag"
    w = Writer(path)
    w.set_compression(getattr(Writer.CompressionFormat, compression.upper()))
    w.chunk_threshold = 100_000
    with w:
        c = w.add_connection(TOPIC, "sensor_msgs/msg/CompressedImage", typestore=ts)
        for i, (t, b) in enumerate(zip(stamps_ns(len(jpegs)), jpegs)):
            msg = CI(header=Hd(seq=i, stamp=T(sec=t // 10**9, nanosec=t % 10**9), frame_id=""), format="jpeg",
                     data=np.frombuffer(b, np.uint8))
            w.write(c, t, ts.serialize_ros1(msg, "sensor_msgs/msg/CompressedImage"))
    whole = list(open_source(path))
    assert len(whole) == len(jpegs) and all(f.ok for f in whole)
    cut = _cut(path, tmp_path / "cut.bag", int(path.stat().st_size * 0.6))
    frames = list(open_source(cut))
    assert frames[-1].error.reason == "truncated"
    good = frames[:-1]
    assert len(good) >= 5
    for i, f in enumerate(good):
        np.testing.assert_array_equal(f.image, decoded(jpegs[i]))


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(fraction=st.floats(0.0, 1.0))
def test_any_cut_point_never_crashes(good_bag, tmp_path, fraction):
    size = good_bag.stat().st_size
    cut = _cut(good_bag, tmp_path / "any.bag", int(size * fraction))
    try:
        src = open_source(cut)
    except SourceError as err:  # only when nothing of the camera topic is left
        assert "cut short" in str(err) or "empty" in str(err)
        return
    frames = list(src)
    assert len(frames) == len(src)
    assert [f.index for f in frames] == list(range(len(frames)))
    assert all(f.ok for f in frames[:-1])
    if fraction < 1.0 and int(size * fraction) < size:
        assert frames[-1].error is not None and frames[-1].error.reason == "truncated"


def test_scan_bag_reads_a_complete_bag(good_bag, jpegs):
    items = list(scan_bag(good_bag))
    assert isinstance(items[-1], ScanEnd) and items[-1].status == "complete"
    msgs = [m for m in items if isinstance(m, RawMessage)]
    assert len(msgs) == len(jpegs)
    assert [m.time_ns for m in msgs] == stamps_ns(len(jpegs))


def _write_bag(path: Path, topics: dict[str, str], messages) -> Path:
    """messages: iterable of (topic, time_ns, message object)."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    with Writer(path) as w:
        conns = {t: w.add_connection(t, ty, typestore=ts) for t, ty in topics.items()}
        for topic, t, msg in messages:
            w.write(conns[topic], t, ts.serialize_ros1(msg, topics[topic]))
    return path


def test_raw_image_topic(tmp_path):
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    names = ("sensor_msgs/msg/Image", "std_msgs/msg/Header", "builtin_interfaces/msg/Time")
    Image, Hd, T = (ts.types[n] for n in names)
    bgr = picture(2, (32, 24))
    msgs = [
        Image(header=Hd(seq=0, stamp=T(sec=5, nanosec=0), frame_id=""), height=24, width=32, encoding="rgb8",
              is_bigendian=0, step=96, data=np.frombuffer(bgr[:, :, ::-1].tobytes(), np.uint8)),
        Image(header=Hd(seq=1, stamp=T(sec=6, nanosec=0), frame_id=""), height=24, width=32, encoding="mono8",
              is_bigendian=0, step=32, data=np.frombuffer(bgr[:, :, 0].tobytes(), np.uint8)),
        Image(header=Hd(seq=2, stamp=T(sec=7, nanosec=0), frame_id=""), height=24, width=32, encoding="16UC1",
              is_bigendian=0, step=64, data=np.zeros(64 * 24, np.uint8)),
    ]
    topic = "/bot/camera_node/image/raw"
    path = _write_bag(tmp_path / "raw.bag", {topic: "sensor_msgs/msg/Image"},
                      [(topic, (5 + i) * 10**9, m) for i, m in enumerate(msgs)])
    frames = list(open_source(path))
    np.testing.assert_array_equal(frames[0].image, bgr)
    assert np.array_equal(frames[1].image[:, :, 1], bgr[:, :, 0])
    assert frames[2].error.reason == "unsupported_encoding"
    assert [f.stamp for f in frames] == [5.0, 6.0, 7.0]


def test_topic_choice_and_wrong_topic(tmp_path, jpegs):
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    CI, Hd, T, S = (ts.types[n] for n in ("sensor_msgs/msg/CompressedImage", "std_msgs/msg/Header",
                                           "builtin_interfaces/msg/Time", "std_msgs/msg/String"))

    def img(i):
        return CI(header=Hd(seq=i, stamp=T(sec=i + 1, nanosec=0), frame_id=""), format="jpeg",
                  data=np.frombuffer(jpegs[i], np.uint8))

    cam, other = "/bot/camera_node/image/compressed", "/bot/debug/image/compressed_overlay"
    topics = {cam: "sensor_msgs/msg/CompressedImage", other: "sensor_msgs/msg/CompressedImage",
              "/bot/log": "std_msgs/msg/String"}
    path = _write_bag(tmp_path / "multi.bag", topics,
                      [(cam, 1 * 10**9, img(0)), (other, 2 * 10**9, img(1)), (cam, 3 * 10**9, img(2)),
                       ("/bot/log", 4 * 10**9, S(data="hello"))])
    assert list_image_topics(path) == sorted([cam, other])
    src = open_source(path)  # the camera topic ends in /image/compressed
    assert src.topic == cam and len(src) == 2
    np.testing.assert_array_equal(list(src)[1].image, decoded(jpegs[2]))
    assert len(open_source(path, topic=other)) == 1
    with pytest.raises(SourceError) as e:
        open_source(path, topic="/bot/camera/image/compressed")
    msg = str(e.value)
    assert "is not in multi.bag" in msg and cam in msg and other in msg
    with pytest.raises(SourceError, match="std_msgs/String, not camera images"):
        open_source(path, topic="/bot/log")


def test_bag_without_image_topic(tmp_path):
    from rosbags.typesys import Stores, get_typestore

    S = get_typestore(Stores.ROS1_NOETIC).types["std_msgs/msg/String"]
    path = _write_bag(tmp_path / "log.bag", {"/rosout_text": "std_msgs/msg/String"},
                      [("/rosout_text", 10**9, S(data="x"))])
    with pytest.raises(SourceError, match="no sensor_msgs/CompressedImage") as e:
        open_source(path)
    assert "/rosout_text" in str(e.value) and "rosbag record" in str(e.value)
    assert list_image_topics(path) == []


# ---------------------------------------------------------------------------- bad specs


def test_missing_path(tmp_path, good_bag):
    with pytest.raises(SourceError, match="does not exist") as e:
        open_source(tmp_path / "intrinsic.bag")  # typo: the file is intrinsics.bag
    assert "intrinsics.bag" in str(e.value)  # lists the recordings that are there
    with pytest.raises(SourceError, match="does not exist"):
        list_image_topics(tmp_path / "nope.bag")


def test_unknown_extension_and_fake_bag(tmp_path):
    (tmp_path / "calib.yaml").write_text("a: 1\n")
    with pytest.raises(SourceError, match=r"pass a ROS 1 bag \(\.bag\), a ROS 2 bag"):
        open_source(tmp_path / "calib.yaml")
    (tmp_path / "fake.bag").write_text("not a bag")
    with pytest.raises(SourceError, match="not a ROS 1 bag"):
        open_source(tmp_path / "fake.bag")
    (tmp_path / "old.bag").write_bytes(b"#ROSBAG V1.2\n" + b"\x00" * 64)
    with pytest.raises(SourceError, match="version 1.2"):
        open_source(tmp_path / "old.bag")
    ros2 = tmp_path / "ros2_bag"
    ros2.mkdir()
    (ros2 / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (ros2 / "ros2_bag_0.db3").write_bytes(b"SQLite format 3\x00")
    with pytest.raises(SourceError, match="ROS 2 bag"):
        open_source(ros2)
    with pytest.raises(SourceError, match="empty source"):
        open_source("  ")


# ---------------------------------------------------------------------------- the guarded decode path
from dtscal_lib.errors import Reason  # noqa: E402
from dtscal_lib.sources import headers  # noqa: E402
from dtscal_lib.sources.bagformat import MAX_CHUNK_BYTES  # noqa: E402
from dtscal_lib.sources.decode import read_image_file  # noqa: E402


@pytest.mark.parametrize("ext", [".jpg", ".png", ".bmp", ".ppm", ".pgm", ".tiff", ".webp", ".pbm"])
def test_read_header_agrees_with_opencv(ext):
    img = picture(3, (37, 23))
    if ext in (".pgm", ".pbm"):
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    ok, buf = cv2.imencode(ext, img)
    assert ok
    h = headers.read_header(buf.tobytes())
    assert (h.width, h.height) == (37, 23)
    assert decode_image(buf.tobytes()).shape == (23, 37, 3)


def test_pam_and_commented_pnm_headers():
    assert headers.read_header(b"P7\nWIDTH 5\nHEIGHT 4\nDEPTH 3\nMAXVAL 255\nTUPLTYPE RGB\nENDHDR\n" + bytes(60)) \
        == headers.ImageHeader("PAM", 5, 4)
    assert headers.read_header(b"P6\n# made by hand\n7 # width\n3\n255\n" + bytes(63)).width == 7


@pytest.mark.parametrize("w, h, reason", [(8192, 6000, None), (8193, 10, Reason.TOO_LARGE),
                                          (8000, 7000, Reason.TOO_LARGE), (0, 10, Reason.CORRUPT_IMAGE)])
def test_dimension_limits(w, h, reason):
    if reason is None:
        headers.check_dimensions(w, h)
        return
    with pytest.raises(FrameError) as e:
        headers.check_dimensions(w, h)
    assert e.value.reason is reason


def test_a_png_beyond_the_limit_is_refused_before_decoding(monkeypatch):
    ok, buf = cv2.imencode(".png", picture(1, (64, 48)))
    monkeypatch.setattr(headers, "MAX_SIDE", 32)
    with pytest.raises(FrameError) as e:
        decode_image(buf.tobytes())
    assert e.value.reason == "too_large" and "64x48" in str(e.value)


@pytest.mark.parametrize("magic, name", [(b"GIF89a", "GIF"), (b"\x76\x2f\x31\x01", "OpenEXR"),
                                         (b"#?RADIANCE\n", "Radiance"), (b"\x59\xa6\x6a\x95", "Sun raster")])
def test_formats_without_a_header_check_are_not_decoded(magic, name):
    with pytest.raises(FrameError) as e:
        decode_image(magic + bytes(64))
    assert e.value.reason is Reason.UNSUPPORTED_FORMAT and name in str(e.value)


def test_a_decoder_exception_is_a_counted_reason(monkeypatch):
    def boom(*_a):
        raise cv2.error("OpenCV(4.x) imdecode_: something inside the codec")

    monkeypatch.setattr(cv2, "imdecode", boom)
    with pytest.raises(FrameError) as e:
        decode_image(jpeg(picture(0)))
    assert e.value.reason is Reason.DECODER_ERROR and "something inside the codec" in str(e.value)


def test_read_image_file_refuses_special_files(tmp_path):
    import os

    os.mkfifo(tmp_path / "pipe.png")
    os.symlink("/dev/null", tmp_path / "null.png")
    for name, what in (("pipe.png", "FIFO"), ("null.png", "character device")):
        with pytest.raises(FrameError) as e:
            read_image_file(tmp_path / name, name)
        assert e.value.reason is Reason.NOT_A_FILE and what in str(e.value)


def test_reasons_are_strings_for_comparison_and_json():
    import json

    assert Reason.NO_BOARD == "no_board" and f"{Reason.TOO_LARGE}" == "too_large"
    assert json.dumps({Reason.SIZE_MISMATCH: 1, "x": Reason.EMPTY}) == '{"size_mismatch": 1, "x": "empty"}'
    assert FrameError("corrupt_jpeg", "m").reason is Reason.CORRUPT_JPEG
    assert FrameError("a_plugin_reason", "m").reason == "a_plugin_reason"


@pytest.mark.parametrize("compression", ["bz2", "lz4"])
def test_a_chunk_that_outgrows_its_declared_size_stops_the_walk(tmp_path, compression, good_bag):
    import bz2

    import lz4.frame

    zeros = bytes(4 << 20)
    payload = bz2.compress(zeros) if compression == "bz2" else lz4.frame.compress(zeros)
    data = good_bag.read_bytes()
    hlen = struct.unpack_from("<I", data, 13)[0]
    at = data.find(b"index_pos=", 17, 17 + hlen) + len(b"index_pos=")
    body = data[: struct.unpack_from("<Q", data, at)[0]]

    def field(k, v):
        f = k + b"=" + v
        return struct.pack("<I", len(f)) + f

    for declared, status in ((1000, "damaged"), (MAX_CHUNK_BYTES + 1, "too_large")):
        head = (field(b"op", b"\x05") + field(b"compression", compression.encode())
                + field(b"size", struct.pack("<I", declared)))
        rec = struct.pack("<I", len(head)) + head + struct.pack("<I", len(payload)) + payload
        path = tmp_path / f"{declared}.bag"
        path.write_bytes(body + rec)
        end = [x for x in scan_bag(path) if isinstance(x, ScanEnd)]
        assert [e.status for e in end] == [status], end
