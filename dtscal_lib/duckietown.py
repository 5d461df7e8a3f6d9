"""Duckietown and ROS facts the kit agrees with: one place, imported everywhere else.

Sources: Duckietown's ``camera_intrinsic/default.yaml`` and ``camera_extrinsic/default.yaml``
as shipped on the robot, ``dts duckiebot calibrate_intrinsics`` (ROS ``camera_calibration``
with ``--size 7x5 --square 0.031``) and the ground-projection code.
"""

from __future__ import annotations

import numpy as np

#: Duckiebot camera image size, (width, height)
IMAGE_SIZE: tuple[int, int] = (640, 480)
#: default frame rate of the camera node
FPS: int = 30

# --- names: every topic, service, path and port of Duckietown's the kit uses, each with its source.
# No other module spells them out (tests/test_duckietown_names.py looks for copies).

#: ROS 1 topic templates; ``{robot}`` is the robot's name (dt-duckiebot-interface, ``camera_driver``'s
#: ``camera_node``: ``~image/compressed``, ``~camera_info``, the ``~set_camera_info`` service)
CAMERA_NODE = "/{robot}/camera_node"
#: the camera topic's last part (a camera's ``image/compressed``, ROS's image_transport naming)
IMAGE_SUFFIX = "/image/compressed"
IMAGE_TOPIC = CAMERA_NODE + IMAGE_SUFFIX
CAMERA_INFO_TOPIC = CAMERA_NODE + "/camera_info"
#: the service ROS's calibrator's COMMIT calls (``sensor_msgs/SetCameraInfo``)
SET_CAMERA_INFO = "set_camera_info"
SET_CAMERA_INFO_SERVICE = CAMERA_NODE + "/" + SET_CAMERA_INFO
#: the ROS master's port (ROS wiki, ``ROS_MASTER_URI``: ``http://localhost:11311`` by default)
ROS_MASTER_PORT = 11311

#: DTPS, Duckietown's pub-sub over HTTP: a robot's switchboard listens on ``<ROBOT>.local:11911``
#: (duckietown-sdk, ``robots/duckiebot/generic.py``: ``DEFAULT_ROBOT_SWITCHBOARD_PORT``; the simulator,
#: Duckiematrix, on 127.0.0.1:7501, ``DEFAULT_DUCKIEMATRIX_PORT``)
DTPS_HOST = "{robot}.local"
DTPS_SWITCHBOARD_PORT = 11911
DTPS_DUCKIEMATRIX_PORT = 7501
#: the camera a robot's SDK reads by default (duckietown-sdk ``DB21J.camera``: ``front_center``)
DTPS_CAMERA_SENSOR = "front_center"
#: a camera's queues on the switchboard, ``<ROBOT>/sensor/camera/<SENSOR>/...`` (dt-duckiebot-interface,
#: ``camera_driver_abs.py``: ``jpeg`` a ``CompressedImage``, ``parameters`` a ``CameraIntrinsicCalibration``,
#: ``info`` a ``Camera``; duckietown-sdk ``DTPSCameraDriver`` reads ``jpeg``)
DTPS_CAMERA_PATH = ("{robot}", "sensor", "camera", "{sensor}")
DTPS_CAMERA_JPEG = "jpeg"
DTPS_CAMERA_PARAMETERS = "parameters"
DTPS_CAMERA_INFO = "info"
#: the robot's key-value store over DTPS (duckietown/dt-kvstore, ``packages/kvstore/main.py``: port 11411;
#: ``/data/config/calibrations/<kind>/<ROBOT>.yaml`` is the read-write queue ``data/calibration/<kind>/current``,
#: written back to that file with ``yaml.dump``; the camera driver subscribes to
#: ``calibration/camera_intrinsic/current`` and republishes its ``parameters``)
KVSTORE_PORT = 11411
KVSTORE_CALIBRATION = ("data", "calibration", "{kind}", "current")

#: where the robot keeps calibrations, relative to its config root (``/data/config``)
INTRINSIC_DIR = "calibrations/camera_intrinsic"
EXTRINSIC_DIR = "calibrations/camera_extrinsic"
ROBOT_CONFIG_ROOT = "/data/config"
ROBOT_CALIBRATIONS = ROBOT_CONFIG_ROOT + "/calibrations"
DEFAULT_NAME = "default"
#: the robot's file server, to which Duckietown's current extrinsic tool POSTs the extrinsic file
#: (lib-dt-computer-vision / dt-files-api: ``http://<ROBOT>.local/files/data/config/...``)
ROBOT_FILES_URL = "http://{host}/files" + ROBOT_CALIBRATIONS + "/{kind}/{robot}.yaml"
#: the robot's login for ``scp`` (Duckietown's SD-card images: user ``duckie``)
ROBOT_USER = "duckie"
#: the container that runs the camera driver (``dts duckiebot``: ``duckiebot-interface``)
INTERFACE_CONTAINER = "duckiebot-interface"


def ros_name(template: str, robot: str) -> str:
    """A ROS name of :data:`IMAGE_TOPIC` & co. for ``robot``."""
    return template.format(robot=robot)


def dtps_camera_path(robot: str, sensor: str = DTPS_CAMERA_SENSOR) -> tuple[str, ...]:
    """The switchboard path of a camera: ``(robot, "sensor", "camera", sensor)``."""
    return tuple(c.format(robot=robot, sensor=sensor) for c in DTPS_CAMERA_PATH)


def kvstore_calibration_path(kind: str) -> tuple[str, ...]:
    """The kvstore queue of ``/data/config/calibrations/<kind>/<ROBOT>.yaml`` (kind ``camera_intrinsic``...)."""
    return tuple(c.format(kind=kind) for c in KVSTORE_CALIBRATION)


#: the shipped ``camera_intrinsic/default.yaml``, value for value
DEFAULT_INTRINSICS: dict = {
    "image_width": 640,
    "image_height": 480,
    "camera_name": "/porsche911/rosberrypi_cam",
    "camera_matrix": {
        "rows": 3,
        "cols": 3,
        "data": [307.7379294605756, 0, 329.692367951685, 0, 314.9827773443905, 244.4605588877848, 0, 0, 1],
    },
    "distortion_model": "plumb_bob",
    "distortion_coefficients": {
        "rows": 1,
        "cols": 5,
        "data": [-0.2565888993516047, 0.04481160508242147, -0.00505275149956019, 0.001308569367976665, 0],
    },
    "rectification_matrix": {"rows": 3, "cols": 3, "data": [1, 0, 0, 0, 1, 0, 0, 0, 1]},
    "projection_matrix": {
        "rows": 3,
        "cols": 4,
        "data": [210.1107940673828, 0, 327.2577820024981, 0, 0, 253.8408660888672, 239.9969353923052, 0, 0, 0, 1, 0],
    },
}

#: the shipped ``camera_extrinsic/default.yaml``: rectified pixel -> ground metres, row-major
DEFAULT_HOMOGRAPHY: list[float] = [
    -4.89775e-05, -0.0002150858, -0.1818273,
    0.00099274, 1.202336e-06, -0.3280241,
    -0.0004281805, -0.007185673, 1,
]


def default_K() -> np.ndarray:
    """The default intrinsic matrix, (3, 3) float64."""
    return np.array(DEFAULT_INTRINSICS["camera_matrix"]["data"], dtype=np.float64).reshape(3, 3)


def default_dist() -> np.ndarray:
    """The default plumb_bob distortion ``[k1, k2, p1, p2, k3]``, (5,) float64."""
    return np.array(DEFAULT_INTRINSICS["distortion_coefficients"]["data"], dtype=np.float64)


def default_P() -> np.ndarray:
    """The default projection matrix ``[K' | 0]``, (3, 4) float64."""
    return np.array(DEFAULT_INTRINSICS["projection_matrix"]["data"], dtype=np.float64).reshape(3, 4)


def default_H() -> np.ndarray:
    """The default ground homography (rectified pixel -> ground metres), (3, 3) float64."""
    return np.array(DEFAULT_HOMOGRAPHY, dtype=np.float64).reshape(3, 3)


# --- ROS camera_calibration (cameracalibrator.py) rules, used by detect/ and coverage.py ---
#: a detection with any corner closer than this to the image border is rejected (pixels)
BORDER_MARGIN_PX = 8
#: X, Y, Size, Skew ranges a full bar needs
PARAM_RANGES = (0.7, 0.7, 0.4, 0.5)
#: a detection is a new sample when its L1 distance to every stored sample exceeds this
SAMPLE_MIN_DISTANCE = 0.2
#: CALIBRATE is enabled at this many samples even if the bars are not full
MAX_SAMPLES_FOR_CALIBRATE = 40
#: a ground homography with H[1][2] > 0 is rejected as corrupt (Duckietown's check)
def homography_is_corrupt(H: np.ndarray) -> bool:
    """Duckietown's sanity check on a ground homography: ``H[1][2] > 0`` means corrupt."""
    return bool(np.asarray(H, dtype=float).reshape(3, 3)[1, 2] > 0)
