"""Beside Nav2: the map updater as a lifecycle node (launch_ros's LifecycleNode) and a Nav2
lifecycle manager that brings it up after map_server and amcl and keeps a bond with it, as
Nav2's own bringup launches its servers. The node takes the reference map from map_server's
``map`` topic and its parameters from ``params_file``.

    ros2 launch lidar_map_updating map_updater.launch.py [params_file:=FILE] [namespace:=NS]
        [autostart:=true] [use_lifecycle_manager:=true] [bond_timeout:=4.0]

With ``use_lifecycle_manager:=false`` no manager is started: add ``map_updater`` to the
``node_names`` of the manager that brings up map_server and amcl instead.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import LifecycleNode, Node
from launch_ros.substitutions import FindPackageShare


def generate_launch_description():
    namespace = LaunchConfiguration("namespace")
    params = LaunchConfiguration("params_file")
    use_sim_time = LaunchConfiguration("use_sim_time")
    default_params = PathJoinSubstitution([FindPackageShare("lidar_map_updating"), "params",
                                           "map_updater.yaml"])
    return LaunchDescription([
        DeclareLaunchArgument("namespace", default_value="", description="the nodes' namespace"),
        DeclareLaunchArgument("params_file", default_value=default_params,
                              description="the node's parameters (YAML)"),
        DeclareLaunchArgument("use_sim_time", default_value="false"),
        DeclareLaunchArgument("autostart", default_value="true",
                              description="the manager configures and activates the node"),
        DeclareLaunchArgument("use_lifecycle_manager", default_value="true"),
        DeclareLaunchArgument("bond_timeout", default_value="4.0",
                              description="[s] the manager's bond timeout (0: no bond)"),
        LifecycleNode(package="lidar_map_updating", executable="map_updater",
                      name="map_updater", namespace=namespace, output="screen",
                      parameters=[params, {"use_sim_time": use_sim_time}]),
        Node(package="nav2_lifecycle_manager", executable="lifecycle_manager",
             name="lifecycle_manager_map_updater", namespace=namespace, output="screen",
             condition=IfCondition(LaunchConfiguration("use_lifecycle_manager")),
             parameters=[{"use_sim_time": use_sim_time,
                          "autostart": LaunchConfiguration("autostart"),
                          "node_names": ["map_updater"],
                          "bond_timeout": LaunchConfiguration("bond_timeout")}]),
    ])
