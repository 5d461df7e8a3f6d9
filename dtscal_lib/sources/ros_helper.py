"""ROS 1 helper process, run on Debian's ``/usr/bin/python3`` (which has ``rospy``), never imported by the kit.

The kit's virtualenv cannot import ``rospy`` (ROS 1 is not on PyPI); this script is started by
:mod:`dtscal_lib.sources.live` and :mod:`dtscal_lib.robot` as a separate process with a clean
environment. It uses only the standard library and ROS's own Python packages.

Modes::

    ros_helper.py subscribe TOPIC     stream CompressedImage messages to stdout
    ros_helper.py set_camera_info SERVICE TIMEOUT   read a CameraInfo as JSON on stdin, call the
                                                    sensor_msgs/SetCameraInfo service, print JSON

Stream protocol (stdout, binary): records of ``kind (1 byte) + length (4 bytes, big-endian) + payload``.
``F``: a frame, payload = header stamp (8-byte big-endian double, seconds) + the JPEG bytes.
``S``: a status, payload = UTF-8 JSON ``{"state": ..., "message": ...}``.
The subscriber uses ``queue_size=1``: when the reader is slow, ROS drops the older messages.
"""

import json
import os
import struct
import sys
import threading
import time
import xmlrpc.client

MASTER = os.environ.get("ROS_MASTER_URI", "http://localhost:11311")
_out_lock = threading.Lock()


class _Transport(xmlrpc.client.Transport):
    def make_connection(self, host):
        conn = super().make_connection(host)
        conn.timeout = 3.0
        return conn


def master_proxy():
    return xmlrpc.client.ServerProxy(MASTER, transport=_Transport())


def master_problem():
    """None when the master answers, else a short description of why not."""
    try:
        code, msg, _ = master_proxy().getSystemState("/dtscal_probe")
        return None if code == 1 else f"it answered {msg!r}"
    except (OSError, xmlrpc.client.Error) as exc:
        return f"{type(exc).__name__}: {exc}"


def _emit(kind, payload):
    with _out_lock:
        out = sys.stdout.buffer
        out.write(kind + struct.pack("!I", len(payload)) + payload)
        out.flush()


def status(state, message):
    _emit(b"S", json.dumps({"state": state, "message": message}).encode())


def subscribe(topic):
    problem = master_problem()
    if problem:
        status("error", f"cannot reach the ROS master at {MASTER} ({problem}); check that the robot is on, "
                        "that ROS_MASTER_URI points at it, and press Reconnect")
        return 3
    import rospy
    from sensor_msgs.msg import CompressedImage

    broken, seen = threading.Event(), threading.Event()

    def on_image(msg):
        if broken.is_set():
            return
        seen.set()
        try:
            _emit(b"F", struct.pack("!d", msg.header.stamp.to_sec()) + bytes(msg.data))
        except (BrokenPipeError, OSError, ValueError):
            broken.set()  # the kit closed the pipe: stop

    rospy.init_node("dtscal_live", anonymous=True, disable_signals=True)
    rospy.Subscriber(topic, CompressedImage, on_image, queue_size=1, buff_size=2 ** 24, tcp_nodelay=True)
    parent = os.getppid()
    last = None
    master = master_proxy()
    while not broken.is_set() and os.getppid() == parent:
        try:
            _code, _msg, state = master.getSystemState("/dtscal_live")
            publishers = [nodes for name, nodes in state[0] if name == topic]
            n = len(publishers[0]) if publishers else 0
        except (OSError, xmlrpc.client.Error) as exc:
            status("error", f"the ROS master at {MASTER} went away ({type(exc).__name__}); frames stop here. "
                            "Start the robot's ROS again (or check the network) and press Reconnect")
            os._exit(4)
        if n:
            now = ("running", f"{topic} has {n} publisher(s) on {MASTER}")
        elif seen.is_set():
            now = ("waiting", (f"nobody publishes {topic} on {MASTER} any more (the bag ended or the camera "
                               "node stopped); frames resume when it is back, or press Reconnect"))
        else:
            now = ("waiting", (f"nobody publishes {topic} on {MASTER} yet: is the robot's camera node running? "
                               "(`rostopic list` on the robot shows its topics)"))
        if now != last:
            status(*now)
            last = now
        time.sleep(0.5)
    os._exit(0)


def set_camera_info(service, timeout):
    import rospy
    from sensor_msgs.msg import CameraInfo
    from sensor_msgs.srv import SetCameraInfo

    def answer(**kw):
        print(json.dumps(kw), flush=True)
        return 0

    data = json.load(sys.stdin)
    problem = master_problem()
    if problem:
        return answer(ok=False, kind="no_master", message=f"cannot reach the ROS master at {MASTER} ({problem})")
    rospy.init_node("dtscal_commit", anonymous=True, disable_signals=True)
    try:
        rospy.wait_for_service(service, timeout=timeout)
    except rospy.ROSException:
        return answer(ok=False, kind="no_service",
                      message=f"no service {service} on the ROS master at {MASTER} within {timeout:g} s")
    info = CameraInfo()
    info.header.stamp = rospy.Time.now()
    info.header.frame_id = data.get("frame_id", "")
    info.width, info.height = int(data["width"]), int(data["height"])
    info.distortion_model = data["distortion_model"]
    info.D = [float(v) for v in data["D"]]
    info.K = [float(v) for v in data["K"]]
    info.R = [float(v) for v in data["R"]]
    info.P = [float(v) for v in data["P"]]
    try:
        call = rospy.ServiceProxy(service, SetCameraInfo)
        res = call(info)
    except (rospy.ServiceException, rospy.ROSException, OSError) as exc:
        return answer(ok=False, kind="call_failed", message=f"calling {service} failed: {exc}")
    return answer(ok=bool(res.success), kind="done" if res.success else "refused", message=res.status_message)


def main(argv):
    if len(argv) >= 2 and argv[0] == "subscribe":
        return subscribe(argv[1])
    if len(argv) >= 3 and argv[0] == "set_camera_info":
        return set_camera_info(argv[1], float(argv[2]))
    print(__doc__, file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
