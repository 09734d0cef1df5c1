"""The live ROS 2 node (``mapupdate ros2``): a lifecycle node on the one robot pipeline.
``node`` is the only module of the project that imports rclpy; ``parameters`` declares and
validates its parameters."""
