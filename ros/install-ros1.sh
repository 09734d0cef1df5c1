#!/bin/sh
# ROS 1 (ros_comm 1.15/1.16) from Debian 12's packages, for the live node and its tests:
# installed when missing and this user may (root with apt-get), then made visible to the
# virtual environment whose python is $1 through a .pth file naming Debian's dist-packages.
# Without it the ROS tests skip, saying why.
set -u
py=${1:?usage: install-ros1.sh VENV_PYTHON}
debs="ros-core python3-rospy python3-rosbag python3-tf2-ros python3-nav-msgs
      python3-sensor-msgs python3-geometry-msgs python3-std-srvs python3-diagnostic-msgs
      python3-map-msgs python3-rostopic python3-rosservice"
dist=/usr/lib/python3/dist-packages
if [ ! -d "$dist/rospy" ] || [ ! -d "$dist/map_msgs" ] || ! command -v roscore >/dev/null; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "installing ROS 1 from Debian's packages (the live node and its tests)"
    { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $debs; } \
      >/dev/null 2>&1 || echo "could not install ROS 1: the ROS tests will skip"
  else
    echo "ROS 1 is not installed (as root: apt-get install $(echo $debs)): the ROS tests will skip"
  fi
fi
if [ -d "$dist/rospy" ]; then
  site=$("$py" -c "import sysconfig; print(sysconfig.get_paths()['purelib'])")
  echo "$dist" > "$site/debian-ros1.pth"
fi
