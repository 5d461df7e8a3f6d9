"""Why a ``ros:`` source gets no frame, in one sentence with the fix (standard library only, no rospy).

:class:`~dtscal_lib.sources.live.RosLive` asks these before and while it waits, so the status
line and the command line say what is wrong within seconds instead of "connecting" forever:

* :func:`master_problem`: ``ROS_MASTER_URI`` unset with no master on this computer, a host name
  that does not resolve, a closed port, a host that does not answer, a port that is not a master;
* :func:`callback_problem`: ``ROS_IP`` / ``ROS_HOSTNAME`` naming an address that is not this
  computer's (the robot would send its frames there: the connection hangs after registering);
* :func:`topic_problem`: the master is up but nobody publishes the camera topic: the robot is
  there without its camera node, or the master knows no robot of that name (the robots whose
  camera topics it has are listed).

Each returns ``None`` when it finds nothing wrong. Timeouts: name resolution 2 s, connection and
answer 3 s each (the master answers on a LAN in milliseconds; a Duckiebot's mDNS name resolves in
well under a second when it is on the network).
"""

from __future__ import annotations

import os
import re
import socket
import threading
import xmlrpc.client
from urllib.parse import urlsplit

from .. import duckietown as dt

RESOLVE_S = 2.0
CONNECT_S = 3.0
RECONNECT = "then press Reconnect"
_CAMERA_TOPIC = re.compile("^" + re.escape(dt.IMAGE_TOPIC).replace(re.escape("{robot}"), "([^/]+)") + "$")


def _resolve(host: str, port: int) -> tuple[list | None, str]:
    """getaddrinfo with a deadline (it has none of its own): (addresses or None, why not)."""
    out: dict = {}

    def run():
        try:
            out["addrs"] = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
        except OSError as exc:
            out["error"] = exc.strerror or str(exc)

    t = threading.Thread(target=run, daemon=True, name="dtscal-resolve")
    t.start()
    t.join(RESOLVE_S)
    if t.is_alive():
        return None, f"no answer within {RESOLVE_S:g} s"
    return out.get("addrs"), out.get("error", "")


class _Transport(xmlrpc.client.Transport):
    def make_connection(self, host):
        conn = super().make_connection(host)
        conn.timeout = CONNECT_S
        return conn


def _master(uri: str):
    return xmlrpc.client.ServerProxy(uri, transport=_Transport())


def master_problem(uri: str, *, uri_was_set: bool = True) -> str | None:
    """Why the ROS master at ``uri`` cannot be used, or None when it answers as a master."""
    parts = urlsplit(uri)
    host, port = parts.hostname or "", parts.port or dt.ROS_MASTER_PORT
    if not uri_was_set:
        where = "ROS_MASTER_URI is not set and no ROS master runs on this computer"
        fix = ("set it to your robot's master before starting JupyterLab or the command "
               f"(export ROS_MASTER_URI=http://ROBOT.local:{dt.ROS_MASTER_PORT}, or pass master_uri= / --master-uri), "
               + RECONNECT)
    else:
        where, fix = None, None
    addrs, why = _resolve(host, port)
    if not addrs:
        if where:
            return f"{where}: {fix}"
        return (f"the robot's name {host} in ROS_MASTER_URI={uri} does not resolve ({why or 'no such name'}): "
                f"check the robot's name and that this computer is on the robot's network (ping {host}), "
                + RECONNECT)
    family, stype, proto, _canon, addr = addrs[0]
    try:
        with socket.socket(family, stype, proto) as s:
            s.settimeout(CONNECT_S)
            s.connect(addr)
    except ConnectionRefusedError:
        if where:
            return f"{where}: {fix}"
        return (f"nothing listens on port {port} of {host} (ROS_MASTER_URI={uri}): the computer is there but no "
                f"ROS master runs on it; start the robot's ROS (or correct the port; ROS uses {dt.ROS_MASTER_PORT}), "
                + RECONNECT)
    except OSError as exc:
        if where:
            return f"{where}: {fix}"
        return (f"{host} does not answer on port {port} ({exc.strerror or type(exc).__name__}; "
                f"ROS_MASTER_URI={uri}): the robot is off, on another network, or a firewall blocks the port; "
                f"check with ping {host}, " + RECONNECT)
    try:
        code, msg, _state = _master(uri).getSystemState("/dtscal_probe")
    except (OSError, xmlrpc.client.Error) as exc:
        return (f"port {port} of {host} answers but not as a ROS master ({type(exc).__name__}; "
                f"ROS_MASTER_URI={uri}): correct the port (ROS uses {dt.ROS_MASTER_PORT}), " + RECONNECT)
    if code != 1:
        return f"the ROS master at {uri} refused a question ({msg!r}): restart the robot's ROS, " + RECONNECT
    return None


def _is_this_computer(address: str) -> bool:
    """True when ``address`` (an IP) belongs to this computer: binding a socket to it works."""
    family = socket.AF_INET6 if ":" in address else socket.AF_INET
    try:
        with socket.socket(family, socket.SOCK_DGRAM) as s:
            s.bind((address, 0))
        return True
    except OSError:
        return False


def callback_problem(env=None) -> str | None:
    """``ROS_IP`` / ``ROS_HOSTNAME`` that are not this computer's, or None.

    ROS tells the robot to send the frames to the address in ``ROS_IP`` (else ``ROS_HOSTNAME``,
    else this computer's host name). One that is not this computer's registers fine and then
    nothing ever arrives.
    """
    env = os.environ if env is None else env
    fix = ("set it to this computer's address on the robot's network (`hostname -I` lists them) or unset it, "
           + RECONNECT)
    ip = (env.get("ROS_IP") or "").strip()
    if ip:
        if not _is_this_computer(ip):
            return (f"ROS_IP={ip} is not an address of this computer, so the robot cannot send the frames back "
                    f"(the connection hangs after registering): {fix}")
        return None
    name = (env.get("ROS_HOSTNAME") or "").strip()
    if name:
        addrs, why = _resolve(name, 0)
        if not addrs:
            return (f"ROS_HOSTNAME={name} does not resolve ({why or 'no such name'}), so the robot cannot send the "
                    f"frames back: {fix}")
        if not any(_is_this_computer(a[4][0]) for a in addrs):
            return (f"ROS_HOSTNAME={name} is not a name of this computer, so the robot cannot send the frames back "
                    f"(the connection hangs after registering): {fix}")
    return None


def camera_robots(state) -> list[str]:
    """The robots whose camera topic has a publisher, from a master's ``getSystemState``."""
    return sorted({m.group(1) for topic, nodes in state[0] if nodes and (m := _CAMERA_TOPIC.match(topic))})


def topic_problem(uri: str, topic: str, robot: str | None) -> str | None:
    """Why nobody publishes ``topic`` on the (answering) master, or None when somebody does."""
    try:
        _code, _msg, state = _master(uri).getSystemState("/dtscal_probe")
    except (OSError, xmlrpc.client.Error):
        return None  # master_problem says it
    if any(t == topic and nodes for t, nodes in state[0]):
        return None
    robots = camera_robots(state)
    # the robot's namespace from what is published or served there (subscriptions do not count: a
    # subscriber of /ROBOT/camera_node/... , such as this kit itself, says nothing about the robot)
    names = {seg for group in (state[0], state[2]) for t, nodes in group if nodes
             for seg in [t.split("/")[1] if t.count("/") > 1 else ""]
             + [n.split("/")[1] for n in nodes if n.count("/") > 1]}
    if robot and robot not in names:
        if robots:
            return (f"the ROS master at {uri} knows no robot named {robot}; it has the camera of "
                    f"{', '.join(robots)}: use ros:{robots[0]}" + (" (or another of these)" if len(robots) > 1 else "")
                    + ", " + RECONNECT)
        return (f"nobody publishes {topic} on the ROS master at {uri}, and no robot's camera is on it: start the "
                f"robot's camera node, or check that ROS_MASTER_URI names your robot's master, " + RECONNECT)
    who = f"the robot {robot} is on the ROS master at {uri} but" if robot else f"on the ROS master at {uri}"
    return (f"{who} nobody publishes {topic}: start its camera node (`rostopic list` on the robot shows what "
            f"runs), " + RECONNECT)
