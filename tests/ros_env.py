"""Real ROS 1 for the tests: a private ``roscore``, process groups, ROS's environment, a Duckiebot camera node.

Shared by test_ros_bag_play, test_ros_live and test_ui_ros (a helper module, not a test file: the fixtures
``ros_ok`` and ``roscore`` are registered in conftest.py). The ROS tools run on Debian's
``/usr/bin/python3`` with a clean environment (no venv, no PYTHONPATH), a private ``roscore`` on a free port,
and ROS_HOME / ROS_LOG_DIR in a temporary folder. Every process is started in its own process group and the
whole group is killed afterwards, whether the test passed or not.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import textwrap
import time
import xmlrpc.client
from contextlib import contextmanager
from pathlib import Path

import pytest

from ci import missing as missing_in_ci

#: the robot of the bundled recording
ROBOT = "synthbot"
SYSTEM_PYTHON = "/usr/bin/python3"
ROS_TOOLS = ("roscore", "rosbag", "rostopic")


def _ros_tool(name: str) -> str | None:
    return shutil.which(name, path="/usr/bin:/bin:/usr/local/bin:" + os.environ.get("PATH", ""))


def _missing_ros() -> str | None:
    missing = [t for t in ROS_TOOLS if _ros_tool(t) is None]
    if not missing and Path(SYSTEM_PYTHON).exists():
        probe = subprocess.run([SYSTEM_PYTHON, "-c", "import rospy, rosbag, sensor_msgs.msg"],
                               env={"PATH": "/usr/bin:/bin"}, capture_output=True, timeout=60)
        if probe.returncode != 0:
            missing.append("rospy/rosbag/sensor_msgs for /usr/bin/python3")
    elif not Path(SYSTEM_PYTHON).exists():
        missing.append(SYSTEM_PYTHON)
    return ", ".join(missing) or None


@pytest.fixture(scope="module")
def ros_ok():
    missing = _missing_ros()
    if missing:
        msg = f"ROS 1 tools missing ({missing}); install them with scripts/install-ros.sh"
        missing_in_ci(msg)


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _ros_env(home: Path, port: int) -> dict[str, str]:
    home.mkdir(parents=True, exist_ok=True)
    return {
        "PATH": "/usr/bin:/bin",
        "HOME": str(home),
        "LANG": "C.UTF-8",
        "ROS_HOME": str(home),
        "ROS_LOG_DIR": str(home / "log"),
        "ROS_MASTER_URI": f"http://127.0.0.1:{port}",
        "ROS_HOSTNAME": "127.0.0.1",
        "PYTHONUNBUFFERED": "1",
    }


def _kill_group(proc: subprocess.Popen, grace: float = 10.0) -> None:
    """SIGINT the process group (ROS shuts down cleanly on it), then SIGKILL what is left."""
    try:
        pgid = os.getpgid(proc.pid)
    except ProcessLookupError:
        proc.wait()
        return
    for sig, wait in ((signal.SIGINT, grace), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(pgid, sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(timeout=wait)
        except subprocess.TimeoutExpired:
            continue
        # the leader is gone; children (rosmaster, rosout) may linger a moment
        deadline = time.time() + wait
        while time.time() < deadline:
            try:
                os.killpg(pgid, 0)
            except ProcessLookupError:
                return
            time.sleep(0.1)
    try:
        os.killpg(pgid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait()


@contextmanager
def _started(cmd: list[str], env: dict[str, str], log: Path):
    """Run ``cmd`` in a new process group; kill the group on exit, however the block ends."""
    with log.open("wb") as out:
        proc = subprocess.Popen(cmd, env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        yield proc
    finally:
        _kill_group(proc)


def _log(path: Path) -> str:
    return path.read_text(errors="replace")[-3000:] if path.exists() else "(no log)"


@pytest.fixture(scope="module")
def roscore(ros_ok, tmp_path_factory):
    """A private ROS master; yields the environment for ROS processes that use it."""
    with running_roscore(tmp_path_factory.mktemp("roshome")) as env:
        yield env


@contextmanager
def running_roscore(home: Path, port: int | None = None):
    """Start ``roscore`` on ``port`` (default a free one), wait until it answers, yield the ROS environment."""
    port = port or _free_port()
    env = _ros_env(home, port)
    log = home / f"roscore-{port}-{time.time_ns()}.log"
    with _started([_ros_tool("roscore"), "-p", str(port)], env, log) as core:
        master = xmlrpc.client.ServerProxy(env["ROS_MASTER_URI"])
        deadline = time.time() + 60
        while True:
            if core.poll() is not None:
                pytest.fail(f"roscore exited with {core.returncode}:\n{_log(log)}")
            try:
                code, _msg, _state = master.getSystemState("/dtscal_test")
                if code == 1:
                    break
            except OSError:
                pass
            if time.time() > deadline:
                pytest.fail(f"roscore did not answer on port {port} within 60 s:\n{_log(log)}")
            time.sleep(0.2)
        yield env


def _run(cmd: list[str], env: dict[str, str], timeout: float = 120) -> subprocess.CompletedProcess:
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        _kill_group(proc, grace=2)
        out, err = proc.communicate()
        pytest.fail(f"{' '.join(cmd)} timed out after {timeout} s:\n{out.decode(errors='replace')}\n"
                    f"{err.decode(errors='replace')}")
    finally:
        if proc.poll() is None:
            _kill_group(proc, grace=2)
    return subprocess.CompletedProcess(cmd, proc.returncode, out.decode(errors="replace"), err.decode(errors="replace"))


CAMERA_NODE = textwrap.dedent('''
    """A Duckiebot camera node's calibration side: set_camera_info writes camera_intrinsic/<ROBOT>.yaml."""
    import os, sys
    import rospy, yaml
    from sensor_msgs.srv import SetCameraInfo, SetCameraInfoResponse

    robot, root = sys.argv[1], sys.argv[2]

    def on_set(req):
        c = req.camera_info
        doc = {"image_width": c.width, "image_height": c.height, "camera_name": "/" + robot + "/camera_node",
               "camera_matrix": {"rows": 3, "cols": 3, "data": list(c.K)},
               "distortion_model": c.distortion_model,
               "distortion_coefficients": {"rows": 1, "cols": len(c.D), "data": list(c.D)},
               "rectification_matrix": {"rows": 3, "cols": 3, "data": list(c.R)},
               "projection_matrix": {"rows": 3, "cols": 4, "data": list(c.P)}}
        path = os.path.join(root, "camera_intrinsic", robot + ".yaml")
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, "w") as f:
            yaml.safe_dump(doc, f)
        return SetCameraInfoResponse(success=True, status_message="Write to " + path)

    rospy.init_node("camera_node", argv=["camera_node", "__ns:=/" + robot], disable_signals=True)
    rospy.Service("/" + robot + "/camera_node/set_camera_info", SetCameraInfo, on_set)
    print("READY", flush=True)
    rospy.spin()
''')


def _wait(pred, timeout: float, what: str, interval: float = 0.1):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        v = pred()
        if v:
            return v
        time.sleep(interval)
    pytest.fail(f"timed out after {timeout} s waiting for {what}")


def _subscribers(env, topic: str) -> int:
    _code, _msg, state = xmlrpc.client.ServerProxy(env["ROS_MASTER_URI"]).getSystemState("/dtscal_test")
    return sum(len(nodes) for name, nodes in state[1] if name == topic)


def _node_pid(uri: str) -> int:
    return xmlrpc.client.ServerProxy(uri).getPid("/dtscal_test")[2]


def _kill_master(env) -> None:
    """SIGKILL rosmaster and rosout (roslaunch runs them in sessions of their own), as a crash would."""
    master = xmlrpc.client.ServerProxy(env["ROS_MASTER_URI"])
    pids = [_node_pid(env["ROS_MASTER_URI"]), _node_pid(master.lookupNode("/dtscal_test", "/rosout")[2])]
    for pid in pids:
        os.kill(pid, signal.SIGKILL)
    for pid in pids:
        _wait(lambda pid=pid: not _alive(pid), 10, f"pid {pid} to die")


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[-1].split()[0] != "Z"  # a zombie is dead
    except FileNotFoundError:
        return False
