"""The ROS 2 package (ament_python): ``ros2 run lidar_map_updating map_updater`` and ``ros2
launch lidar_map_updating map_updater.launch.py`` in a colcon workspace. The node itself is
the Python project's (``mapupdate ros2``), installed with pip."""

from glob import glob

from setuptools import setup

PACKAGE = "lidar_map_updating"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=[],
    # a plain script, not an entry point: the project's own distribution is also called
    # lidar-map-updating, and an entry point's wrapper would look for it there
    scripts=["scripts/map_updater"],
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
        (f"share/{PACKAGE}/params", glob("params/*.yaml")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="lidar-map-updating maintainers",
    maintainer_email="maintainers@example.org",
    description="The map updater as a ROS 2 lifecycle node beside Nav2",
    license="MIT",
)
