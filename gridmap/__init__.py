"""The occupancy grid: shared types, map_server I/O, ray casting, log-odds mapping and map
metrics. Imports nothing else of this project, and no numba until a kernel is needed."""

from .map_io import MapFileError, load_map, save_map
from .types import FREE, OCCUPIED, UNKNOWN, GridError, OccupancyGrid, Pose2D, Scan, wrap_angle

__all__ = ["FREE", "OCCUPIED", "UNKNOWN", "GridError", "MapFileError", "OccupancyGrid", "Pose2D",
           "Scan", "load_map", "save_map", "wrap_angle"]
