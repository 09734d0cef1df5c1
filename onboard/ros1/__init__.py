"""The live ROS 1 node (``mapupdate ros1``): a thin layer on the one robot pipeline. ``node``
is the only module of the project that imports rospy; ``settings`` and ``grids`` are plain
Python, tested without ROS."""
