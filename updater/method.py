"""What updates a map, as the robot pipeline sees it. The paper's ``MapUpdater`` implements
this interface, and so do the other methods a robot or a study may run in its place (the
log-odds baselines and the hybrid of ``onboard.methods``): the pipeline, the log replay, the
ROS node and the simulated sessions know a method only through it."""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, runtime_checkable

from gridmap import OccupancyGrid, Pose2D, PoseVerdict, Scan

from .map_updater import ScanReport

# asked, for a scan past the gate, whether its sensor pose is to be used, refined or refused
PoseCheckCall = Callable[[], PoseVerdict]


@runtime_checkable
class MapMethod(Protocol):
    """One scan at a time in, the map as it stands out."""

    def process(self, scan: Scan, sensor_pose: Pose2D, odometry: Pose2D | None = None,
                pose_check: PoseCheckCall | None = None) -> ScanReport:
        """Use one scan taken at ``sensor_pose`` (map frame; ``odometry``: the robot's
        odom-frame pose, for the gate); the report says what became of it and the pose it
        was placed at."""

    def updated_map(self) -> OccupancyGrid:
        """The map as it stands."""

    def state_bytes(self) -> int:
        """Bytes of state the method keeps for the map (for the resource tables)."""
