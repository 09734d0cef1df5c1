"""What the ROS 1 and ROS 2 nodes share, in plain Python (no ROS import, tested without ROS):
their settings and parameter validation (``settings``), map messages as fields and the box of
changed cells (``grids``), and the counters they report on ``/diagnostics`` (``health``)."""
