"""ROS 2 recordings (a DD24-B's ``.mcap`` / ``.db3``) are sources like a ROS 1 ``.bag``.

Small bags are written from the bundled session with ``rosbags``' own ROS 2 writer: MCAP with
``CompressedImage`` and SQLite 3 with ``Image`` (``bgr8``) and a ``camera_info`` topic. What the kit reads from
them must be what it reads from the ROS 1 bag: the same frames, pixel for pixel, and the camera_info's K.
"""

from __future__ import annotations

import numpy as np
import pytest

from dtscal_lib import datasets
from dtscal_lib import duckietown as dt
from dtscal_lib.sources import BagSource, Ros2BagSource, open_live, open_source, write_ros2_image_bag

TOPIC = "/dd24b/camera/image/compressed"
STEP, N = 40, 6


@pytest.fixture(scope="module")
def recording():
    ros1 = BagSource(datasets.session_dir() / "intrinsics.bag")
    jpegs = [(stamp, data) for i, stamp, data in ros1.compressed_images() if i % STEP == 0][:N]
    frames = [f for f in ros1 if f.index % STEP == 0][:N]
    return jpegs, frames


@pytest.fixture(scope="module")
def bags(recording, tmp_path_factory):
    jpegs, _ = recording
    base = tmp_path_factory.mktemp("ros2")
    info = {"width": 640, "height": 480, "K": dt.default_K().ravel().tolist(), "D": dt.default_dist().tolist(),
            "P": dt.default_P().ravel().tolist()}
    mcap = write_ros2_image_bag(base / "mcap_bag", TOPIC, jpegs, storage="mcap")
    db3 = write_ros2_image_bag(base / "db3_bag", TOPIC.replace("/compressed", "_raw"), jpegs, storage="sqlite3",
                               raw=True, camera_info=info)
    return mcap, db3


def _same_frames(src, frames):
    got = list(src)
    assert len(got) == len(frames) == len(src)
    for a, b in zip(got, frames):
        assert a.ok, a.error
        assert np.array_equal(a.image, b.image)
        assert a.stamp == pytest.approx(b.stamp)


def test_mcap_compressed_images_read_like_the_ros1_bag(bags, recording):
    mcap, _ = bags
    for spec in (mcap, next(mcap.glob("*.mcap"))):  # the bag's folder, or its storage file alone
        src = open_source(spec)
        assert isinstance(src, Ros2BagSource) and src.topic == TOPIC and src.camera_info is None
        assert "ROS 2 bag" in src.describe()
        _same_frames(src, recording[1])


def test_db3_raw_images_and_camera_info(bags, recording):
    _, db3 = bags
    src = open_source(next(db3.glob("*.db3")))
    assert src.msgtype == "sensor_msgs/msg/Image"
    _same_frames(src, recording[1])
    assert src.camera_info["K"] == pytest.approx(dt.default_K().ravel().tolist())
    assert (src.camera_info["width"], src.camera_info["height"]) == (640, 480)
    assert "camera_info on" in src.describe()


def test_a_ros2_bag_plays_as_a_live_camera(bags):
    with open_live(str(bags[0]), realtime=False) as cam:
        f = cam.latest(timeout=10)
        assert f is not None and f.image.shape == (480, 640, 3)
