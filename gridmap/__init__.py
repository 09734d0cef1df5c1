"""The occupancy grid: shared types, map_server I/O, ray casting, log-odds mapping and map
metrics. Imports nothing else of this project, and no numba until a kernel is needed."""

from .cells import FREE, OCCUPIED, UNKNOWN
from .errors import MapUpdatingError
from .map_io import MapFileError, load_map, save_map
from .types import GridError, OccupancyGrid, Pose2D, Scan, wrap_angle
from .verdict import PoseVerdict, Verdict

__all__ = ["FREE", "OCCUPIED", "UNKNOWN", "GridError", "MapFileError", "MapUpdatingError",
           "OccupancyGrid", "Pose2D", "PoseVerdict", "Scan", "Verdict", "load_map", "save_map",
           "wrap_angle"]
