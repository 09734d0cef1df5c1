"""The map updater of docs/algorithm.md: keeps an occupancy grid true while the world changes.

Imports nothing of this project but ``gridmap``; numba is imported on first use.

    from updater import MapUpdater, UpdaterConfig
    updater = MapUpdater(reference_map, UpdaterConfig(gating=True))
    report = updater.process(scan, sensor_pose, odometry)   # once per scan
    grid = updater.updated_map()                             # at any time
"""

from .config import UpdaterConfig, UpdaterError
from .faces import FaceCounts
from .map_updater import MapUpdater, ScanReport, ScanStatus
from .method import MapMethod, PoseCheckCall
from .verdicts import BEAM_CHANGE, BEAM_INVALID, BEAM_SKIPPED, BEAM_UNCHANGED, BeamVerdict

__all__ = ["UpdaterConfig", "UpdaterError", "FaceCounts", "MapUpdater", "MapMethod", "PoseCheckCall",
           "ScanReport", "ScanStatus",
           "BeamVerdict", "BEAM_INVALID", "BEAM_UNCHANGED", "BEAM_SKIPPED", "BEAM_CHANGE"]
