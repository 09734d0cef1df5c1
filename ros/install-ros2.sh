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
  # tf2_msgs and map_msgs from their definitions (no wheel carries them)
  [ -d "$venv/share/tf2_msgs" ] && [ -d "$venv/share/map_msgs" ] && return 0
  echo "building tf2_msgs and map_msgs into $venv (/tf for the node's poses, the costmap's updates)"
  sh ros/build-ros2-msgs.sh "$venv" >>"$venv.log" 2>&1 ||
    echo "could not build tf2_msgs and map_msgs (see $venv.log): the node's tf tests will skip"
}
if [ -x "$venv/bin/mapupdate" ] && [ "$venv/bin/mapupdate" -nt pyproject.toml ]; then
  msgs
  exit 0
fi
if ! "$py" -c 'import sys, platform; sys.exit(not (sys.version_info[:2] == (3, 11) and platform.machine() == "x86_64"))'; then
  echo "the ROS 2 Jazzy wheels need Python 3.11 on x86_64: the ROS 2 tests will skip"
  exit 0
fi
echo "installing ROS 2 Jazzy's wheels into $venv (the live ROS 2 node and its tests)"
{ "$py" -m venv "$venv" && "$venv/bin/pip" install --quiet --upgrade pip &&
  "$venv/bin/pip" install --quiet -e '.[ros2]' 'cyclonedds>=0.10'; } >"$venv.log" 2>&1 \
  && touch "$venv/bin/mapupdate" && msgs \
  || echo "could not install the ROS 2 wheels (see $venv.log): the ROS 2 tests will skip"
