"""A LaserScan message as the nodes take it: converted as a recording's scans are
(``robotlogs.rosbag.scan_record``), or the reason to skip it, for ``/diagnostics``."""

from __future__ import annotations

import numpy as np

from gridmap import MapUpdatingError
from robotlogs.rosbag import scan_record


def usable_scan(msg, topic: str):
    """(record, None) for a scan the node can use; (None, (why, detail)) for one to skip."""
    try:
        rec = scan_record(msg, topic)
    except MapUpdatingError as e:
        return None, ("malformed scan", e)
    if rec.scan.beams == 0:
        return None, ("empty scan", topic)
    if rec.time == 0.0:
        # no time to look its poses up at (ROS 1 reads 0 as "the latest"), nor to gate by
        return None, ("scan stamped 0", topic)
    return rec, None


def has_bad_ranges(rec) -> bool:
    """Whether some readings are NaN or negative (invalid beams; the others are used)."""
    with np.errstate(invalid="ignore"):
        return bool(np.any(~(rec.scan.ranges >= 0)))
