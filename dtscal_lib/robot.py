"""COMMIT: send a calibration to a robot, over DTPS (today's robots) or over ROS 1.

* **Over DTPS** (:func:`commit_dtps`; a Duckiebot on ``ente`` and a DD24-B): the robot's key-value store
  (``dt-kvstore``, ``<ROBOT>.local:11411``) serves ``/data/config/calibrations/<kind>/<ROBOT>.yaml`` as the
  read-write queue ``data/calibration/<kind>/current``. COMMIT publishes the file's content there (a CBOR
  mapping, as the store's ``YAMLFileAdapter`` expects), reads the queue back and says so only when the robot
  holds exactly what was sent; the store writes the file, and the camera driver, subscribed to
  ``calibration/camera_intrinsic/current``, takes the new intrinsics at once (dt-duckiebot-interface,
  ``camera_driver_abs.py``). A robot whose image has no key-value store (older ``ente`` images) refuses
  with a connection error: the message says what to copy where.
* Over ROS 1, intrinsics go where ROS's ``cameracalibrator`` sends them: the camera node's
  ``/<ROBOT>/camera_node/set_camera_info`` service (``sensor_msgs/SetCameraInfo``). The
  Duckiebot's camera node writes what it receives to
  ``/data/config/calibrations/camera_intrinsic/<ROBOT>.yaml`` and answers with a status message.
  The call is made by Debian's ``rospy`` in a helper process (see :mod:`dtscal_lib.sources.live`).
* Extrinsics have no ROS service on a Duckiebot. Duckietown's current extrinsic tool uploads the
  file with an HTTP POST to the robot's file server,
  ``http://<ROBOT>.local/files/data/config/calibrations/camera_extrinsic/<ROBOT>.yaml``;
  :func:`commit_extrinsics` does the same with the file the kit wrote (classic or version 2).

Every failure raises :class:`CommitError` with what to do; the local file is never touched.
"""

from __future__ import annotations

import json
import subprocess
import urllib.error
import urllib.parse
import urllib.request
from pathlib import Path


from . import calib_files, safe_yaml
from . import duckietown as dt
from .errors import DtscalError

#: where the robot keeps its calibrations
ROBOT_CALIBRATIONS = dt.ROBOT_CALIBRATIONS


class CommitError(DtscalError):
    """A calibration could not be sent to the robot; the message says what to do (the local file is intact)."""


def _robot(robot: str) -> str:
    if not calib_files.is_robot_name(robot):
        raise CommitError(f"robot name {robot!r} is not a Duckiebot name (letters, digits, '_'); pass --robot NAME")
    return robot


def _by_hand(kind: str, robot: str, calib_file) -> str:
    host = dt.DTPS_HOST.format(robot=robot)
    return (f"the file {calib_file} is kept; to install it by hand: scp {calib_file} "
            f"{dt.ROBOT_USER}@{host}:{ROBOT_CALIBRATIONS}/{kind}/{robot}.yaml and restart the robot's interface "
            f"container (`docker -H {host} restart {dt.INTERFACE_CONTAINER}`)")


def camera_info_dict(calib: calib_files.IntrinsicCalibration, frame_id: str = "") -> dict:
    """The fields of a ``sensor_msgs/CameraInfo`` for an intrinsic calibration (plain lists)."""
    return {"width": int(calib.width), "height": int(calib.height), "distortion_model": calib.distortion_model,
            "D": [float(v) for v in calib.D], "K": [float(v) for v in calib.K.ravel()],
            "R": [float(v) for v in calib.R.ravel()], "P": [float(v) for v in calib.P.ravel()],
            "frame_id": frame_id}


def commit_intrinsics(robot: str, calib_file, *, master_uri: str | None = None, timeout: float = 10.0) -> str:
    """Send an intrinsic YAML to ``/<robot>/camera_node/set_camera_info``, as ROS's calibrator's COMMIT does.

    Parameters
    ----------
    robot : the Duckiebot's name
    calib_file : a ``camera_intrinsic/<robot>.yaml`` (validated before anything is sent)
    master_uri : the robot's ROS master (default ``$ROS_MASTER_URI``)
    timeout : seconds to wait for the service to appear

    Returns
    -------
    str : the service's ``status_message`` (the camera node says where it wrote the file)

    Raises
    ------
    CommitError
        ROS missing on this computer, master unreachable, no such service, the node refused.
    """
    from .sources.live import run_ros_helper

    robot = _robot(robot)
    try:
        calib = calib_files.load_intrinsics(calib_file)
    except DtscalError as exc:
        raise CommitError(f"nothing was sent to {robot}: {exc}") from None
    service = dt.ros_name(dt.SET_CAMERA_INFO_SERVICE, robot)
    request = json.dumps(camera_info_dict(calib, frame_id=f"{robot}/camera_optical_frame")).encode()
    try:
        proc = run_ros_helper([dt.SET_CAMERA_INFO, service, f"{float(timeout):g}"], master=master_uri,
                              stdin=request, timeout=float(timeout) + 60.0)
    except DtscalError as exc:
        raise CommitError(f"cannot talk ROS to {robot}: {exc}. {_by_hand('camera_intrinsic', robot, calib_file)}") \
            from None
    except subprocess.TimeoutExpired:
        raise CommitError(f"{service} did not answer within {timeout + 60:g} s; "
                          f"{_by_hand('camera_intrinsic', robot, calib_file)}") from None
    lines = proc.stdout.decode(errors="replace").strip().splitlines()
    try:
        answer = json.loads(lines[-1])
    except (IndexError, ValueError):
        err = " | ".join(proc.stderr.decode(errors="replace").strip().splitlines()[-3:])
        raise CommitError(f"the ROS helper failed (exit {proc.returncode}): {err or 'no output'}; "
                          f"{_by_hand('camera_intrinsic', robot, calib_file)}") from None
    if answer.get("ok"):
        return str(answer.get("message", ""))
    advice = {
        "no_master": "check that the robot is on and that ROS_MASTER_URI (or --master-uri) points at it, "
                     f"e.g. http://{dt.DTPS_HOST.format(robot=robot)}:{dt.ROS_MASTER_PORT}",
        "no_service": f"is the camera node of {robot} running? (`rosservice list | grep {dt.SET_CAMERA_INFO}`)",
        "refused": "the camera node refused the calibration",
    }.get(answer.get("kind"), "")
    raise CommitError(f"COMMIT to {robot} failed: {answer.get('message')}" + (f"; {advice}" if advice else "")
                      + f". {_by_hand('camera_intrinsic', robot, calib_file)}")


def robot_files_url(robot: str, master_uri: str | None = None, kind: str = "camera_extrinsic") -> str:
    """``http://<host>/files/data/config/calibrations/<kind>/<robot>.yaml`` on the robot's file server.

    The host is that of ``master_uri`` when given (the robot runs its master), else ``<robot>.local``.
    """
    host = urllib.parse.urlparse(master_uri).hostname if master_uri else None
    return dt.ROBOT_FILES_URL.format(host=host or dt.DTPS_HOST.format(robot=robot), kind=kind, robot=robot)


def commit_extrinsics(robot: str, calib_file, *, master_uri: str | None = None, timeout: float = 10.0,
                      url: str | None = None) -> str:
    """Upload an extrinsic file to the robot the way Duckietown's current extrinsic tool does (HTTP POST).

    The file's bytes are posted unchanged to ``url`` (default :func:`robot_files_url`), where
    the robot's file server stores them as ``camera_extrinsic/<robot>.yaml``. Returns a sentence
    saying where it went. There is no ROS service for extrinsics on a Duckiebot.
    """
    robot = _robot(robot)
    path = Path(calib_file)
    _file_content("camera_extrinsic", robot, path)  # validated before anything is sent
    try:
        body = safe_yaml.read_text_file(path).encode("utf-8")  # regular files only, within the size limit
    except (OSError, DtscalError) as exc:
        raise CommitError(f"cannot read {path} ({exc}); nothing was sent") from None
    target = url or robot_files_url(robot, master_uri)
    req = urllib.request.Request(target, data=body, method="POST", headers={"Content-Type": "text/plain"})
    try:
        with urllib.request.urlopen(req, timeout=float(timeout)) as resp:
            code = resp.status
    except urllib.error.HTTPError as exc:
        raise CommitError(f"the robot's file server refused the upload to {target} (HTTP {exc.code}); "
                          f"{_by_hand('camera_extrinsic', robot, path)}") from None
    except (urllib.error.URLError, OSError) as exc:
        reason = exc.reason if isinstance(exc, urllib.error.URLError) else exc  # urllib's own .reason
        raise CommitError(f"cannot reach the robot's file server at {target} ({reason}); is {robot} on the "
                          f"network? {_by_hand('camera_extrinsic', robot, path)}") from None
    return f"uploaded {path} to {target} (HTTP {code})"


def _file_content(kind: str, robot: str, path: Path) -> dict:
    """The content of a calibration file as the robot's key-value store holds it (validated first)."""
    try:
        if kind == "camera_intrinsic":
            return calib_files.load_intrinsics(path).to_dict()
        doc = safe_yaml.load_yaml_text(safe_yaml.read_text_file(path), str(path))
        if not isinstance(doc, dict) or "homography" not in doc:
            raise CommitError(f"{path} is not an extrinsic file (no homography:); nothing was sent")
        if "version" not in doc:
            calib_files.load_extrinsics(path)
        return doc
    except OSError as exc:
        raise CommitError(f"cannot read {path} ({exc}); nothing was sent") from None
    except CommitError:
        raise
    except DtscalError as exc:
        raise CommitError(f"nothing was sent to {robot}: {exc}") from None


def commit_dtps(link, calib_file, *, kind: str = "camera_intrinsic", timeout: float = 10.0) -> str:
    """Store a calibration file on the robot through its key-value store over DTPS; returns a sentence.

    Parameters
    ----------
    link : a :class:`dtscal_lib.dtps_link.DtpsRobot` (the live source's ``.dtps``, or
        :func:`dtscal_lib.dtps_link.parse_dtps_spec` of ``ROBOT[@HOST]``)
    calib_file : ``camera_intrinsic/<ROBOT>.yaml`` or ``camera_extrinsic/<ROBOT>.yaml`` (validated first)
    kind : ``"camera_intrinsic"`` or ``"camera_extrinsic"``
    timeout : seconds for the whole exchange

    Raises
    ------
    CommitError
        The store cannot be reached, refuses the value (an HTTP error) or holds something else afterwards;
        the message says what to copy where by hand.
    """
    from .dtps_link import import_dtps, run_async

    robot = _robot(link.robot)
    path = Path(calib_file)
    content = _file_content(kind, robot, path)
    by_hand = _by_hand(kind, robot, path)
    where = f"{link.kvstore_url}{'/'.join(dt.kvstore_calibration_path(kind))}/"
    try:
        dtps = import_dtps()[0]
    except DtscalError as exc:
        raise CommitError(f"{exc}; {by_hand}") from None

    async def exchange():
        cxt = await dtps.context(f"dtscal-kvstore-{robot}", urls=[link.kvstore_url])
        try:
            queue = cxt.navigate(*dt.kvstore_calibration_path(kind))
            await queue.publish(dtps.RawData.cbor_from_native_object(content))
            return (await queue.data_get()).get_as_native_object()
        finally:
            await cxt.aclose()

    try:
        stored = run_async(exchange(), float(timeout))
    except TimeoutError:
        raise CommitError(f"the robot's key-value store at {where} did not answer within {timeout:g} s; is {robot} "
                          f"on the network? {by_hand}") from None
    except Exception as exc:  # noqa: BLE001 (aiohttp's and dtps's errors, each said in the robot's words)
        status = getattr(exc, "status", None)
        if status is not None:
            said = " ".join(str(getattr(exc, "message", "")).split())
            raise CommitError(f"{robot} refused the calibration (HTTP {status} from {where}: {said}); nothing "
                              f"changed on the robot. {by_hand}") from None
        raise CommitError(f"cannot reach the robot's key-value store at {where} ({type(exc).__name__}: {exc}); "
                          f"a robot without it (an older image) takes the file by hand: {by_hand}") from None
    if stored != content:
        raise CommitError(f"{robot} did not keep the calibration: {where} holds something else after COMMIT. "
                          f"{by_hand}")
    return (f"stored as {ROBOT_CALIBRATIONS}/{kind}/{robot}.yaml on {robot} through its key-value store "
            f"({where})")


__all__ = ["CommitError", "camera_info_dict", "commit_dtps", "commit_extrinsics", "commit_intrinsics",
           "robot_files_url"]
