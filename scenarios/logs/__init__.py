"""Recorded robot data: CARMEN logs, ROS 1 and ROS 2 bags, and the map update that replays them."""
