"""The ROS 2 package's entry point: the node is the Python project's ``mapupdate ros2``."""
