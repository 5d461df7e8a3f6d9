#!/usr/bin/env bash
# Install the Debian (bookworm) packages of ROS 1 that the kit's real-ROS tests use:
#   roscore, rosbag (record / play / info), rostopic, rospy and sensor_msgs for /usr/bin/python3.
#
# Idempotent: when every tool is already there it prints so and exits without touching apt.
# Needs root (or sudo). Usage:  scripts/install-ros.sh
# The ROS tools run on Debian's /usr/bin/python3, not on the project's venv.
set -euo pipefail

PACKAGES=(ros-core python3-rospy python3-sensor-msgs python3-rosbag python3-rostopic)

have_all() {
    command -v roscore >/dev/null 2>&1 &&
    command -v rosbag >/dev/null 2>&1 &&
    command -v rostopic >/dev/null 2>&1 &&
    /usr/bin/python3 -c 'import rospy, rosbag, sensor_msgs.msg' >/dev/null 2>&1
}

if have_all; then
    echo "install-ros: ROS tools already installed (roscore, rosbag, rostopic, rospy, sensor_msgs); nothing to do."
    exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null 2>&1; then
        SUDO="sudo"
    else
        echo "install-ros: need root (or sudo) to run apt-get; re-run as root." >&2
        exit 1
    fi
fi

export DEBIAN_FRONTEND=noninteractive
# shellcheck source=apt-wait.sh
source "$(dirname "$0")/apt-wait.sh"   # wait for another apt-get instead of failing

# refresh the package lists only when apt does not know the packages yet
if ! apt-cache policy ros-core 2>/dev/null | grep -q 'Candidate: [0-9]'; then
    echo "install-ros: apt does not know ros-core yet; running apt-get update"
    apt_get install-ros update
fi

missing=()
for p in "${PACKAGES[@]}"; do
    if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed'; then
        missing+=("$p")
    fi
done

if [ "${#missing[@]}" -gt 0 ]; then
    echo "install-ros: installing ${missing[*]}"
    apt_get install-ros install -y --no-install-recommends "${missing[@]}"
fi

if have_all; then
    echo "install-ros: done; roscore at $(command -v roscore), rosbag at $(command -v rosbag)"
else
    echo "install-ros: packages installed but a tool is still missing (roscore/rosbag/rostopic or rospy for /usr/bin/python3)" >&2
    exit 1
fi
