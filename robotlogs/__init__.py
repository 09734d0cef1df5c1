"""Recorded robot data: CARMEN logs, ROS 1 and ROS 2 bags, read into plain records and into
observations (a scan with every pose the log gives at its time). Imports only ``gridmap``.

    from robotlogs import log_observations
    found = log_observations("run.bag")
    for obs in found.observations: ...

Readers yield the plain records of :mod:`.records`; :class:`BagWriter` writes them, so simulated
sessions can be stored as bags. Every error a user's file can cause is a :class:`LogError`.
Heavy imports (rosbags) wait until they are needed. The map update that replays a log is
``onboard.replay.update_from_log``.
"""

from .carmen import CarmenLog, parse_carmen, read_carmen
from .observations import (FORMATS, LogObservations, Observation, detect_format,
                           log_observations)
from .records import (LogError, OdomRecord, PoseRecord, ReadStats, Record, ScanRecord,
                      TransformRecord)
from .rosbag import BagTopics, BagWriter, bag_topics, read_bag, resolve_topics, write_bag
from .text_lines import LogLimits

__all__ = ["FORMATS", "BagTopics", "BagWriter", "CarmenLog", "LogError", "LogLimits",
           "LogObservations", "Observation", "OdomRecord", "PoseRecord", "ReadStats", "Record",
           "ScanRecord", "TransformRecord", "bag_topics", "detect_format", "log_observations",
           "parse_carmen", "read_bag", "read_carmen", "resolve_topics", "write_bag"]
