"""The live ROS 2 node (``mapupdate ros2``): a lifecycle node on the one robot pipeline
(``node``), its parameters (``parameters``), and two small tools for a machine without the
``ros2`` command: ``play`` replays a recording into the graph, ``trigger`` calls the node's
services. Only these three modules import rclpy."""
