"""Recorded robot data: CARMEN logs, ROS 1 and ROS 2 bags, and the map update that replays them.

    from scenarios.logs import update_from_log
    summary = update_from_log("map.yaml", "run.bag", "updated.yaml", state_path="state.npz")

Readers yield the plain records of :mod:`.records`; :class:`BagWriter` writes them, so simulated
sessions can be stored as bags. Every error a user's file can cause is a :class:`LogError`.
Heavy imports (rosbags, the updater, the localiser, tqdm) wait until they are needed.
"""

from .carmen import CarmenLog, parse_carmen, read_carmen
from .records import (LogError, OdomRecord, PoseRecord, ReadStats, Record, ScanRecord,
                      TransformRecord)
from .replay import POSE_SOURCES, detect_format, update_from_log
from .rosbag import BagTopics, BagWriter, bag_topics, read_bag, resolve_topics, write_bag

__all__ = ["POSE_SOURCES", "BagTopics", "BagWriter", "CarmenLog", "LogError", "OdomRecord",
           "PoseRecord", "ReadStats", "Record", "ScanRecord", "TransformRecord", "bag_topics",
           "detect_format", "parse_carmen", "read_bag", "read_carmen", "resolve_topics",
           "update_from_log", "write_bag"]
