"""``ros2 run lidar_map_updating map_updater [--map MAP.yaml] [--ros-args ...]``: the lifecycle
node, as ``mapupdate ros2`` runs it (launch_ros's LifecycleNode starts it so)."""

import sys


def main() -> int:
    try:
        from mapupdate import main as mapupdate
    except ImportError:
        sys.exit("map_updater needs the Python project: pip install 'lidar-map-updating[ros2]'")
    return mapupdate(["ros2", *sys.argv[1:]])


if __name__ == "__main__":
    sys.exit(main())
