"""The robot software: what runs on a robot or on its recordings.

- ``pipeline``: one scan's way through the gate, the pose check and the map update, used by
  every front end;
- ``methods``: what updates the map (the paper's updater, or the log-odds and hybrid
  alternatives), behind one interface (``updater.MapMethod``);
- ``robot_config``: the updater, localiser and pose-check settings from one YAML file;
- ``replay``: ``mapupdate update``, a recorded log replayed through the pipeline;
- ``logmap``: ``mapupdate map``, a first map from a log with corrected poses;
- ``outputs``: the rule that no output is written over an input;
- ``ros1``: the live ROS 1 node.

Nothing here imports the simulator or the testbed's front ends (pymunk, gymnasium, rerun,
matplotlib), so a robot installs only numpy, numba, PyYAML, Pillow and rosbags.
"""
