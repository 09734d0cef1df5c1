#!/bin/sh
# ROS 2 Jazzy from the package index's wheels, for the live ROS 2 node and its tests, in an
# environment of its own (.venv-ros2): their message packages (sensor_msgs, nav_msgs, ...)
# share their names with ROS 1's, which the main environment links in from Debian. Where the
# wheels cannot be had (they are built for Python 3.11 on Linux x86_64), the ROS 2 tests skip,
# saying why.
set -u
py=${1:?usage: install-ros2.sh PYTHON}
venv=.venv-ros2
msgs() {
  # tf2_msgs, map_msgs, bond and nav2_msgs' SaveMap from their definitions (no wheel carries
  # them), and colcon to build the ROS 2 package as a workspace would
  [ -d "$venv/share/tf2_msgs" ] && [ -d "$venv/share/map_msgs" ] && [ -d "$venv/share/bond" ] &&
    [ -d "$venv/share/nav2_msgs" ] && [ -x "$venv/bin/colcon" ] && return 0
  echo "building tf2_msgs, map_msgs, bond and nav2_msgs into $venv (/tf, the costmap's updates, Nav2's bond and SaveMap)"
  sh ros/build-ros2-msgs.sh "$venv" >>"$venv.log" 2>&1 ||
    echo "could not build the messages (see $venv.log): the node's tf tests will skip"
  "$venv/bin/pip" install --quiet colcon-core colcon-ros colcon-python-setup-py \
    ros-jazzy-ament-cmake-python >>"$venv.log" 2>&1 ||
    echo "could not install colcon (see $venv.log): the package build test will skip"
}
if [ -x "$venv/bin/mapupdate" ] && [ "$venv/bin/mapupdate" -nt pyproject.toml ]; then
  # a node with a PostgreSQL store needs psycopg (an environment made before it was asked for)
  "$venv/bin/python" -c 'import psycopg' 2>/dev/null ||
    "$venv/bin/pip" install --quiet 'psycopg[binary]>=3.1' >>"$venv.log" 2>&1 ||
    echo "could not install psycopg into $venv (see $venv.log): the ROS 2 store tests will skip"
  msgs
  exit 0
fi
if ! "$py" -c 'import sys, platform; sys.exit(not (sys.version_info[:2] == (3, 11) and platform.machine() == "x86_64"))'; then
  echo "the ROS 2 Jazzy wheels need Python 3.11 on x86_64: the ROS 2 tests will skip"
  exit 0
fi
echo "installing ROS 2 Jazzy's wheels into $venv (the live ROS 2 node and its tests)"
{ "$py" -m venv "$venv" && "$venv/bin/pip" install --quiet --upgrade pip &&
  "$venv/bin/pip" install --quiet -e '.[ros2,store]' 'cyclonedds>=0.10'; } >"$venv.log" 2>&1 \
  && touch "$venv/bin/mapupdate" && msgs \
  || echo "could not install the ROS 2 wheels (see $venv.log): the ROS 2 tests will skip"
