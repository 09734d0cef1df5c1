"""The occupancy grid: shared types, map_server I/O, ray casting, distance fields, log-odds
mapping and map metrics. Imports nothing else of this project."""

from .types import FREE, OCCUPIED, UNKNOWN, GridError, OccupancyGrid, Pose2D, Scan, wrap_angle

__all__ = ["FREE", "OCCUPIED", "UNKNOWN", "GridError", "OccupancyGrid", "Pose2D", "Scan",
           "wrap_angle"]
