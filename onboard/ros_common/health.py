"""What a live node reports on ``/diagnostics``: its own counters, the pipeline's, and the
time each scan took."""

from __future__ import annotations

import collections

import numpy as np


class Health:
    """Counters and per-scan times, for /diagnostics and the log."""

    def __init__(self):
        self.counts = collections.Counter()
        self.skipped = collections.Counter()     # why scans or maps were not used
        self.notes: dict[str, str] = {}          # what a counter cannot say (a map switched)
        self.times: collections.deque = collections.deque(maxlen=500)   # [s] per scan
        # [s] from a scan's arrival to the end of its update (waiting for odometry included)
        self.latencies: collections.deque = collections.deque(maxlen=2000)

    def values(self, pipeline_counts: dict) -> list[tuple[str, str]]:
        """(key, value) pairs: the node's counters, then ``pipeline_counts`` (a dict value, as
        ``gated_by``, one pair per entry: "gated_by: fast turn"), then what was skipped."""
        t = np.asarray(self.times) * 1e3
        out = [(k, str(v)) for k, v in sorted(self.counts.items())]
        for k, v in pipeline_counts.items():
            if isinstance(v, dict):
                out += [(f"{k}: {name}", str(n)) for name, n in sorted(v.items())]
            else:
                out.append((k, str(v)))
        out += [(f"skipped: {k}", str(v)) for k, v in sorted(self.skipped.items())]
        out += sorted(self.notes.items())
        if t.size:
            out += [("scan_time_ms_mean", f"{t.mean():.3f}"), ("scan_time_ms_max",
                                                              f"{t.max():.3f}")]
        if self.latencies:
            lat = np.asarray(self.latencies) * 1e3
            out += [("scan_latency_ms_p50", f"{np.percentile(lat, 50):.3f}"),
                    ("scan_latency_ms_p99", f"{np.percentile(lat, 99):.3f}")]
        return out


def pipeline_values(pipeline, method: str) -> dict:
    """What /diagnostics shows of the pipeline: the method, its counters (the gate's refusals
    by rule in ``gated_by``) and, for the paper's updater, the cells whose evidence of change
    stayed below the threshold (``pending_cells``, of them ``pending_few_observations`` and
    ``pending_outvoted``; counted over the whole map at each publication, as the map is) and,
    with a pose check, whether it holds every scan as the localiser's being lost
    (``pose_check_lost``: ``PoseCheckConfig.lost_after``)."""
    out = {"method": method, **pipeline.counts.as_dict()}
    if pipeline.pose_check is not None:
        out["pose_check_lost"] = str(pipeline.pose_check.lost).lower()
    evidence = getattr(pipeline.updater, "evidence_summary", None)
    if evidence is not None:
        out.update({k: v for k, v in evidence().items() if v is not None})
    return out
