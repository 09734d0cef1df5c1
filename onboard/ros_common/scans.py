"""A LaserScan message as the nodes take it: converted as a recording's scans are
(``robotlogs.rosbag.scan_record``), or the reason to skip it, for ``/diagnostics``."""

from __future__ import annotations

import math

import numpy as np

from gridmap import MapUpdatingError
from robotlogs.rosbag import scan_record

MAX_BEAMS = 20_000     # the default bound: 0.018 deg over a whole turn, past any 2D lidar's


def usable_scan(msg, topic: str, max_beams: int = MAX_BEAMS):
    """(record, None) for a scan the node can use; (None, (why, detail)) for one to skip. A
    scan of more than ``max_beams`` beams is refused before it is read: a corrupt or hostile
    one of millions would hold the node for minutes."""
    beams = len(msg.ranges)
    if beams > max_beams:
        return None, ("scan with more beams than max_beams", f"{beams} > {max_beams} on {topic}")
    try:
        rec = scan_record(msg, topic)
    except MapUpdatingError as e:
        return None, ("malformed scan", e)
    if rec.scan.beams == 0:
        return None, ("empty scan", topic)
    if rec.time == 0.0:
        # no time to look its poses up at (ROS 1 reads 0 as "the latest"), nor to gate by
        return None, ("scan stamped 0", topic)
    step = abs(rec.scan.angle_increment)
    if (rec.scan.beams - 1) * step > 2 * math.pi + step:
        return None, ("scan spanning more than one turn",
                      f"{(rec.scan.beams - 1) * step:.4g} rad on {topic}")
    return rec, None


def has_bad_ranges(rec) -> bool:
    """Whether some readings are NaN or negative (invalid beams; the others are used)."""
    with np.errstate(invalid="ignore"):
        return bool(np.any(~(rec.scan.ranges >= 0)))
