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

# shellcheck source=apt-wait.sh
source "$(dirname "$0")/apt-wait.sh"   # waits for another apt-get instead of failing
apt_sudo install-ros
apt_install_missing install-ros "${PACKAGES[@]}"

if have_all; then
    echo "install-ros: done; roscore at $(command -v roscore), rosbag at $(command -v rosbag)"
else
    echo "install-ros: packages installed but a tool is still missing (roscore/rosbag/rostopic or rospy for /usr/bin/python3)" >&2
    exit 1
fi
