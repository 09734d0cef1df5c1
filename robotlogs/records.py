"""The plain records every log reader yields and the bag writer takes, and the error they raise.

Times are seconds [s] as recorded (message header stamps for bags, the logging host's clock
for CARMEN). Poses are :class:`gridmap.Pose2D` in the frame the record names.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from gridmap import MapUpdatingError, OccupancyGrid, Pose2D, Scan

# How many problem messages a reader keeps verbatim; the rest are only counted.
MAX_PROBLEMS = 20


class LogError(MapUpdatingError, ValueError):
    """A log that cannot be read or used; the message names the file, line or topic."""


@dataclass(frozen=True)
class ScanRecord:
    """One lidar scan.

    ``laser_pose`` is the laser's pose in the map frame when the log carries it (corrected
    CARMEN logs); ``odom_pose`` the robot's odometry pose at scan time when the log carries it
    (CARMEN laser lines). Bag scans leave both None: their poses come from tf and odometry.
    """

    time: float
    scan: Scan
    frame_id: str = "laser"
    topic: str = "/scan"
    laser_pose: Pose2D | None = None
    odom_pose: Pose2D | None = None


@dataclass(frozen=True)
class OdomRecord:
    """Wheel odometry: the pose of ``child_frame_id`` in ``frame_id`` and its velocity
    (vx [m/s], vy [m/s], wz [rad/s]) in the child frame."""

    time: float
    pose: Pose2D
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    frame_id: str = "odom"
    child_frame_id: str = "base_link"
    topic: str = "/odom"


@dataclass(frozen=True)
class TransformRecord:
    """One tf edge: the pose of ``child`` in ``parent``; ``static`` for /tf_static."""

    time: float
    parent: str
    child: str
    pose: Pose2D
    static: bool = False


@dataclass(frozen=True)
class PoseRecord:
    """A pose estimate or a true pose in ``frame_id``, with an optional 3 x 3 covariance over
    (x [m], y [m], yaw [rad]). The topic tells which: /amcl_pose, /ground_truth/pose, ..."""

    time: float
    pose: Pose2D
    topic: str = "/amcl_pose"
    frame_id: str = "map"
    covariance: np.ndarray | None = None


@dataclass(frozen=True)
class MapRecord:
    """An occupancy grid as a map server publishes it (latched, in ``frame_id``)."""

    time: float
    grid: OccupancyGrid
    topic: str = "/map"
    frame_id: str = "map"


Record = ScanRecord | OdomRecord | TransformRecord | PoseRecord | MapRecord


@dataclass
class ReadStats:
    """What a lenient reader skipped: counts per problem kind and the first few messages."""

    skipped: Counter = field(default_factory=Counter)
    ignored: Counter = field(default_factory=Counter)  # known, well-formed, not used
    problems: list[str] = field(default_factory=list)
    first: dict = field(default_factory=dict)   # kind -> the first message of that kind
    invalid_ranges: int = 0          # NaN or negative readings kept as invalid beams ...
    scans_with_invalid_ranges: int = 0   # ... in this many scans
    cut: str = ""                    # how a log cut short ended, "" for a whole one

    def skip(self, kind: str, message: str) -> None:
        self.skipped[kind] += 1
        self.first.setdefault(kind, message)
        if len(self.problems) < MAX_PROBLEMS:
            self.problems.append(message)

    def count_invalid_ranges(self, ranges: np.ndarray) -> None:
        """Count a kept scan's invalid readings: NaN or negative."""
        bad = int(np.count_nonzero(~(ranges >= 0)))
        if bad:
            self.invalid_ranges += bad
            self.scans_with_invalid_ranges += 1

    def merge(self, other: ReadStats) -> None:
        """Add ``other``'s counts (a reader's own stats into the caller's)."""
        self.skipped.update(other.skipped)
        self.ignored.update(other.ignored)
        self.problems.extend(other.problems[:max(MAX_PROBLEMS - len(self.problems), 0)])
        for kind, message in other.first.items():
            self.first.setdefault(kind, message)
        self.invalid_ranges += other.invalid_ranges
        self.scans_with_invalid_ranges += other.scans_with_invalid_ranges
        self.cut = self.cut or other.cut

    @property
    def total_skipped(self) -> int:
        return int(sum(self.skipped.values()))

    def summary(self) -> str:
        """One line for the user: what was skipped and why, or that nothing was."""
        if not self.skipped:
            return "nothing skipped"
        kinds = ", ".join(f"{n} {kind}" for kind, n in self.skipped.most_common())
        first = f"; first: {self.problems[0]}" if self.problems else ""
        return f"skipped {self.total_skipped} ({kinds}){first}"

    def lines(self) -> list[str]:
        """What was skipped, one line per kind (with the first message of that kind), the
        invalid readings kept, and a warning for a log cut short; empty when nothing was."""
        out = []
        for kind, n in self.skipped.most_common():
            first = self.first.get(kind, "")
            out.append(f"skipped {n} ({kind})" + (f"; first: {first}" if first else ""))
        if self.invalid_ranges:
            out.append(f"kept {self.scans_with_invalid_ranges} scans with "
                       f"{self.invalid_ranges} invalid ranges (NaN or negative) as invalid beams")
        if self.cut:
            out.append(f"warning: {self.cut}")
        return out

    def as_dict(self) -> dict:
        return {"skipped": dict(self.skipped), "ignored": dict(self.ignored),
                "problems": list(self.problems), "invalid_ranges": self.invalid_ranges,
                "scans_with_invalid_ranges": self.scans_with_invalid_ranges, "cut": self.cut}
