"""The live ROS 2 node (``mapupdate ros2``): a lifecycle node on the one robot pipeline
(``node``), its lifecycle services (``lifecycle``), its parameters (``parameters``), its
services and publications (``services``) and its bond with Nav2's lifecycle manager
(``bond``). Only these modules import rclpy and ROS 2's messages."""
