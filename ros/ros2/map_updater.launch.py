"""Beside Nav2: the map updater as a lifecycle node that Nav2's lifecycle manager brings up
after map_server and amcl (add "map_updater" to its node_names), on the reference map that
map_server publishes, with the parameters of map_updater.yaml.

    ros2 launch map_updater.launch.py params_file:=/path/to/map_updater.yaml
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess
from launch.substitutions import LaunchConfiguration


def generate_launch_description():
    params = LaunchConfiguration("params_file")
    return LaunchDescription([
        DeclareLaunchArgument("params_file", description="the node's parameters (YAML)"),
        # `mapupdate ros2` is the console script `pip install 'lidar-map-updating[ros2]'`
        # puts on the PATH; without --map it takes the reference map from the 'map' topic
        ExecuteProcess(cmd=["mapupdate", "ros2", "--ros-args", "--params-file", params],
                       output="screen"),
    ])
