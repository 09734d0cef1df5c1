"""Is the localiser tracking the robot? A verdict after each filter update, so that a localiser
that has lost track, or has not yet found the robot after a global start, stops feeding the map
updater until it is sure again.

Two kinds of evidence, one cheap and one costly:

- the filter's own: the heaviest particle cluster must hold ``min_cluster_share`` of the weight
  and its position and heading spreads must stay within ``max_position_std`` and
  ``max_yaw_std_deg``. An odometry jump (a driver's glitch, 100 m between two scans) scatters
  the particles: the heaviest cluster then holds a fifth of the weight, often a single
  particle. A global start is as scattered until the scans have narrowed it down;
- the scan's, scored as the pose check scores it (``PoseCheck.fit``): the scan must fit the map
  at the estimate (a mean capped residual of at most ``max_fit``) and no pose nearby may fit it
  clearly better (``PoseCheck.better_nearby``). A filter that has settled in the wrong place
  looks confident (spreads of 5-10 cm): after a 100 m jump in the simulated warehouse, and a
  start over the whole map, one settled in the wrong aisle with a fit of 0.51-0.58 where the
  right pose scores 0.05-0.10 and no pose within a metre scored better. So the scan must fit
  too, ``settle_updates`` times running, before a lost or converging filter is trusted.

A tracking filter is judged by its spreads alone, which cost nothing, and by the updater: when
its lost check drops ``lost_scans`` processed scans in a row, most beams of each disagreeing
with the map, the pose is taken to be wrong (``observe_lost``). A filter that stays unsure for
``relocalise_after`` updates is started again over the whole map (``initialize_global``), with
a particle count that grows with the free area.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np

from gridmap import OccupancyGrid, Pose2D, Scan
from gridmap.config import check_bounds

from .config import LocalizationError
from .confidence import PoseCheck, PoseCheckConfig


class TrackState(enum.Enum):
    TRACKING = "tracking"        # trusted: its poses may change the map
    CONVERGING = "converging"    # started over the whole map, not yet sure where the robot is
    LOST = "lost"                # was tracking, then became unsure


@dataclass(frozen=True)
class TrackEvent:
    """A change of state at scan time ``time`` [s], and why."""

    time: float
    state: TrackState
    reason: str


# The range of every number (docs/reliability.md).
TRACKING_BOUNDS = {
    "min_cluster_share": (0.0, 1.0), "max_position_std": (0.0, 100.0),
    "max_yaw_std_deg": (0.0, 180.0), "settle_updates": (1, 1000), "max_fit": (0.0, 1.0),
    "lost_cluster_share": (0.0, 1.0), "lost_position_std": (0.0, 100.0),
    "lost_yaw_std_deg": (0.0, 180.0), "lost_scans": (1, 1000), "relocalise_after": (0, 100_000),
    "global_particles_per_m2": (0.0, 1000.0), "min_global_particles": (1, 1_000_000),
    "max_global_particles": (1, 1_000_000),
}


@dataclass(frozen=True)
class TrackingConfig:
    # Trusted again (or at last, after a global start) when, ``settle_updates`` times running,
    # the heaviest cluster holds this share of the weight [1], the position and heading
    # spreads [m, deg] stay within these (sqrt of the largest eigenvalue of the x-y covariance;
    # the pose check's own bounds), and the scan agrees with the map there:
    min_cluster_share: float = 0.9
    max_position_std: float = 0.15
    max_yaw_std_deg: float = 5.0
    settle_updates: int = 3
    max_fit: float = 0.3               # [1] the pose check's fit (0 perfect, 1 nothing fits)
    # Lost, when tracking, once the filter's spreads pass these looser bounds: a filter
    # turning on the spot spreads its headings to 6 deg for a moment and is not lost for that.
    lost_cluster_share: float = 0.5
    lost_position_std: float = 0.3
    lost_yaw_std_deg: float = 10.0
    lost_scans: int = 3                # scans dropped in a row by the updater's lost check
    relocalise_after: int = 30         # unsure updates before a global restart; 0: never
    global_particles_per_m2: float = 30.0   # [1/m^2] of free space, for a global start ...
    min_global_particles: int = 5000        # ... within these bounds
    max_global_particles: int = 100000

    def __post_init__(self):
        try:
            check_bounds(self, TRACKING_BOUNDS, LocalizationError)
        except LocalizationError as e:
            raise LocalizationError(str(e).replace("config key", "tracking key")) from None
        if not self.lost_cluster_share <= self.min_cluster_share <= 1:
            raise LocalizationError("tracking keys 'lost_cluster_share' and "
                                    "'min_cluster_share' must satisfy lost <= min <= 1")
        if self.lost_position_std < self.max_position_std or \
                self.lost_yaw_std_deg < self.max_yaw_std_deg:
            raise LocalizationError("tracking keys 'lost_position_std' and "
                                    "'lost_yaw_std_deg' must be at least 'max_position_std' "
                                    "and 'max_yaw_std_deg'")
        if self.min_global_particles > self.max_global_particles:
            raise LocalizationError("tracking keys 'min_global_particles' and "
                                    "'max_global_particles' must satisfy min <= max")


class TrackingMonitor:
    """The tracking verdict for one localiser on one map. ``observe`` after each filter update;
    ``state`` at any scan; ``events`` for the record. ``converging=True`` for a filter started
    over the whole map, which must settle before it is trusted; a filter started at a given
    pose is trusted until its spreads say otherwise."""

    def __init__(self, grid: OccupancyGrid, config: TrackingConfig | None = None,
                 pose_check_config: PoseCheckConfig | None = None, converging: bool = False):
        self.config = TrackingConfig() if config is None else config
        self._check = PoseCheck(grid, pose_check_config)
        self.state = TrackState.CONVERGING if converging else TrackState.TRACKING
        self.events: list[TrackEvent] = []
        self.restarts = 0          # global restarts made
        self._streak = 0           # confident, agreeing updates in a row
        self._unsure = 0           # updates since trust was lost (or since the last start)
        self._dropped = 0          # processed scans in a row the updater dropped as lost

    @property
    def tracking(self) -> bool:
        return self.state is TrackState.TRACKING

    @property
    def never_tracked(self) -> bool:
        """Started over the whole map, and never settled since."""
        return bool(self.events) and self.events[0].state is TrackState.CONVERGING and \
            not any(e.state is TrackState.TRACKING for e in self.events)

    def global_particles(self, localizer) -> int:
        c = self.config
        n = int(round(localizer.free_area * c.global_particles_per_m2))
        return int(np.clip(n, c.min_global_particles, c.max_global_particles))

    def start_global(self, localizer, time: float, reason: str) -> None:
        """Start ``localizer`` over the whole map and wait for it to settle."""
        localizer.initialize_global(self.global_particles(localizer))
        self._change(time, TrackState.CONVERGING, reason)

    def observe(self, localizer, scan: Scan, robot_pose: Pose2D, sensor_mount: Pose2D
                ) -> TrackState:
        """Judge the filter after an update that used ``scan``; ``robot_pose`` is its estimate
        at the scan. May restart the filter over the whole map (see the module docstring)."""
        t = float(scan.time)
        if self.state is TrackState.TRACKING:
            doubt = self.doubt(localizer.estimate(), lost=True)
            if doubt:
                self._change(t, TrackState.LOST, doubt)
            return self.state
        doubt = self.doubt(localizer.estimate())
        agrees = not doubt and self._fits(scan, robot_pose, sensor_mount)
        self._streak = self._streak + 1 if agrees else 0
        self._unsure += 1
        if self._streak >= self.config.settle_updates:
            self._change(t, TrackState.TRACKING, "confident, and the scans fit the map there")
        elif self.config.relocalise_after and self._unsure >= self.config.relocalise_after:
            self.restarts += 1
            self.start_global(localizer, t, f"unsure for {self._unsure} filter updates: "
                                            "started again over the whole map")
        return self.state

    def observe_lost(self, dropped: bool, time: float) -> None:
        """Tell the monitor whether the updater's lost check dropped a scan it processed."""
        self._dropped = self._dropped + 1 if dropped else 0
        if self.state is TrackState.TRACKING and self._dropped >= self.config.lost_scans:
            self._change(time, TrackState.LOST, f"the updater's lost check dropped "
                                                f"{self._dropped} scans in a row")

    def _fits(self, scan: Scan, robot_pose: Pose2D, sensor_mount: Pose2D) -> bool:
        f = self._check.fit(scan, robot_pose, sensor_mount)
        return f is not None and f.fit <= self.config.max_fit and \
            not self._check.better_nearby(f)

    def doubt(self, estimate, lost: bool = False) -> str:
        """Why the filter's own spreads leave the estimate unsure ("" when they do not): by the
        bounds for trusting it, or with ``lost`` by the looser ones for losing trust."""
        c = self.config
        share, std_max, yaw_max = (c.lost_cluster_share, c.lost_position_std,
                                   c.lost_yaw_std_deg) if lost else \
            (c.min_cluster_share, c.max_position_std, c.max_yaw_std_deg)
        if estimate.cluster_weight < share:
            return (f"heaviest particle cluster holds {100 * estimate.cluster_weight:.0f} % of "
                    f"the weight")
        cov = np.asarray(estimate.cov, np.float64)
        if not np.all(np.isfinite(cov)):
            return "covariance not finite"
        std = math.sqrt(max(float(np.linalg.eigvalsh(cov[:2, :2]).max()), 0.0))
        if std > std_max:
            return f"position std {std:.2f} m"
        yaw = math.degrees(math.sqrt(max(float(cov[2, 2]), 0.0)))
        if yaw > yaw_max:
            return f"yaw std {yaw:.1f} deg"
        return ""

    def _change(self, time: float, state: TrackState, reason: str) -> None:
        self.state = state
        self._streak = 0
        self._unsure = 0
        self._dropped = 0
        self.events.append(TrackEvent(time, state, reason))
