"""Step 0 of docs/algorithm.md, gating: which scans the updater processes at all.

A scan is processed only if at least ``gate_min_interval`` passed since the last processed scan
AND the robot moved ``gate_min_distance`` or turned ``gate_min_rotation_deg`` since then. After
any angular velocity of ``gate_fast_turn_deg_s`` or more, the gate stays shut until
``gate_recovery_time`` passed and ``gate_recovery_distance`` was travelled.

Motion and angular velocity come from odometry (the odom-frame pose at the scan's time), which is
smooth, differenced from scan to scan. Without odometry the localised poses are used, differenced
over at least ``gate_velocity_window`` seconds: localised poses are noisy, and 0.5 deg of yaw
noise at 10 Hz would already read as a fast turn. If the source changes (odometry given for some
scans and not others), motion is measured afresh from the first pose of the new source.

With ``gate_turn_cover`` (not in the authors' code), a scan that turned enough but did not move
is processed only while some direction it sees has been seen fewer than ``gate_turn_views``
times from this place (since the last scan processed for moving): a robot spinning in place
looks round that many times, then holds its scans back as views already taken.
"""

from __future__ import annotations

import math

import numpy as np

from gridmap import Pose2D, wrap_angle

from .config import UpdaterConfig

# Why a scan was not processed (ScanReport.reason).
GATED_INTERVAL = "interval"      # too soon after the last processed scan
GATED_NO_MOTION = "no motion"    # neither moved nor turned enough since then
GATED_FAST_TURN = "fast turn"    # idle after a fast turn
GATED_TIME_BACK = "time went backwards"   # the gate restarts from this scan
GATED_TURN_VIEWS = "turning in place"     # turned, but every heading was seen from here
SKIPPED_OFF_MAP = "sensor off the map"    # not gating: the scan cannot be classified
# Scans held back as a view already taken: with ``gate_confirm`` their unchanged flags are used.
CONFIRMING = frozenset({GATED_INTERVAL, GATED_NO_MOTION, GATED_TURN_VIEWS})

# [s] Scan times are floats: 10 Hz stamps such as 0.7 - 0.4 come out 0.29999999999999993, and
# stamps carried from a ROS clock (1.7e9 s) are rounded to 0.24 us. Intervals are compared with
# this much tolerance, so that the same scans pass whatever the clock's offset.
TIME_TOLERANCE = 1e-6

_FIELDS = ("source", "last_t", "last_x", "last_y", "last_th", "proc_t", "proc_x", "proc_y",
           "proc_th", "idle", "idle_t", "travel", "turn_views")
# gate_turn_views counts the views of each direction from one place in bins of this many degrees
DIRECTION_BIN_DEG = 10.0
DIRECTION_BINS = int(round(360.0 / DIRECTION_BIN_DEG))
_CENTRES = (np.arange(DIRECTION_BINS) + 0.5) * DIRECTION_BIN_DEG
_EVERY_DIRECTION = np.ones(DIRECTION_BINS, bool)
_ALL_BINS = list(range(DIRECTION_BINS))
_TWICE = _ALL_BINS * 2


def _sees(k: int, degrees: float, half: float) -> bool:
    """``directions_seen``'s test for bin k (any whole number: taken round the circle), in the
    same floating-point operations."""
    centre = (k % DIRECTION_BINS + 0.5) * DIRECTION_BIN_DEG
    return abs((centre - degrees + 180.0) % 360.0 - 180.0) <= half


def bins_seen(heading: float, fov_deg: float) -> list[int]:
    """The bins ``directions_seen`` sets, as a list of indices (each once, in no order). A scan
    sees an arc of bins, so only the bins at its ends are put to the test (a NumPy pass over
    every bin cost a scan more than the rest of the gate), and the arc is a slice of the
    bins laid out twice."""
    if fov_deg >= 360.0:
        return _ALL_BINS
    degrees, half = math.degrees(heading), fov_deg / 2.0
    own = int(degrees % 360.0 // DIRECTION_BIN_DEG) % DIRECTION_BINS
    if not _sees(own, degrees, half) and not _sees(own - 1, degrees, half) \
            and not _sees(own + 1, degrees, half):
        return [own]        # an arc narrower than a bin, between two centres
    # the bounds are a bin out at most either way: the test decides
    lo = math.floor((degrees - half) / DIRECTION_BIN_DEG - 0.5) - 1
    while not _sees(lo, degrees, half):
        lo += 1
    hi = math.ceil((degrees + half) / DIRECTION_BIN_DEG - 0.5) + 1
    while not _sees(hi, degrees, half):
        hi -= 1
    if hi - lo >= DIRECTION_BINS - 2:     # the ends meet behind the scan: test every bin
        return [k for k in _ALL_BINS if k == own or _sees(k, degrees, half)]
    start = lo % DIRECTION_BINS
    seen = _TWICE[start:start + hi - lo + 1]
    return seen if (own - lo) % DIRECTION_BINS <= hi - lo else seen + [own]


def directions_seen(heading: float, fov_deg: float) -> np.ndarray:
    """The direction bins (of ``DIRECTION_BIN_DEG``, from heading 0) whose centre a scan at
    ``heading`` [rad] covering ``fov_deg`` about it sees, and always the bin of the heading
    itself: a bool array of ``DIRECTION_BINS``."""
    if fov_deg >= 360.0:
        return _EVERY_DIRECTION
    degrees = math.degrees(heading)
    off = (_CENTRES - degrees + 180.0) % 360.0 - 180.0
    seen = np.abs(off) <= fov_deg / 2.0
    seen[int(degrees % 360.0 // DIRECTION_BIN_DEG) % DIRECTION_BINS] = True
    return seen


class Gate:
    """The gating state machine. ``check`` sees every scan; ``mark_processed`` is called for
    each scan that was processed (not for those dropped as lost, so that the next scan may try
    again as soon as localisation recovers)."""

    def __init__(self, config: UpdaterConfig):
        self.config = config
        self.reset()

    def reset(self) -> None:
        self.source = ""           # "odometry" or "localised": where the poses come from
        self.last_t = math.nan     # the last pose sample, for velocity and travel
        self.last_x = self.last_y = self.last_th = math.nan
        self.proc_t = math.nan     # the last processed scan
        self.proc_x = self.proc_y = self.proc_th = math.nan
        self.idle = False          # shut after a fast turn
        self.idle_t = math.nan     # time of the last fast turn
        self.travel = 0.0          # [m] travelled since then
        # views of each direction from the place of the last scan processed for moving
        self.turn_views = np.zeros(DIRECTION_BINS, np.int64)
        self._by_turn = False      # the scan just let through was for turning alone ...
        self._view = (0.0, 360.0)  # ... and saw about this heading [rad] this angle [deg]
        self._last_seen = (None, [])

    # Which directions a scan sees is worked out only when a rule reads it: most scans are
    # let through for moving, and their views are read, if ever, at a later turn.
    @property
    def turn_views(self) -> np.ndarray:
        return np.array(self._counted(), np.int64)

    @turn_views.setter
    def turn_views(self, views) -> None:
        self._views, self._views_of = [int(v) for v in views], None

    def _counted(self) -> list[int]:
        """The views of each direction (a list: the rules read and add a few bins a scan)."""
        if self._views_of is not None:
            self._views = [0] * DIRECTION_BINS
            for k in self._seen(*self._views_of):
                self._views[k] = 1
            self._views_of = None
        return self._views

    def _seen(self, heading: float, fov_deg: float) -> list[int]:
        if not self.config.gate_turn_cover:
            return _ALL_BINS
        if self._last_seen[0] != (heading, fov_deg):   # a scan's turn rule, then its views
            self._last_seen = ((heading, fov_deg), bins_seen(heading, fov_deg))
        return self._last_seen[1]

    def check(self, t: float, pose: Pose2D, from_odometry: bool, fov_deg: float = 360.0) -> str:
        """"" when the scan at time ``t`` [s] may be processed, else why not. ``fov_deg``: the
        angle the scan covers (for ``gate_turn_cover``)."""
        source = "odometry" if from_odometry else "localised"
        if source != self.source:
            self.source = source
            self._sample(t, pose)
            if not math.isnan(self.proc_t):
                self.proc_x, self.proc_y, self.proc_th = pose.x, pose.y, pose.theta
        elif t < self.last_t:
            self.reset()
            return GATED_TIME_BACK
        else:
            self._observe_motion(t, pose, from_odometry)
        self._by_turn = False
        self._view = (pose.theta, fov_deg)
        if math.isnan(self.proc_t):
            return ""
        return self._reason(t, pose)

    def mark_processed(self, t: float, pose: Pose2D) -> None:
        self.proc_t, self.proc_x, self.proc_y, self.proc_th = t, pose.x, pose.y, pose.theta
        if self._by_turn:
            views = self._counted()
            for k in self._seen(*self._view):
                views[k] += 1
        else:
            self._views_of = self._view     # those of this scan alone

    def _sample(self, t, pose):
        self.last_t, self.last_x, self.last_y, self.last_th = t, pose.x, pose.y, pose.theta

    def _observe_motion(self, t, pose, from_odometry):
        dt = t - self.last_t
        window = 0.0 if from_odometry else self.config.gate_velocity_window
        if dt <= 0 or dt < window:
            return
        turn = abs(wrap_angle(pose.theta - self.last_th))
        if self.idle:
            self.travel += math.hypot(pose.x - self.last_x, pose.y - self.last_y)
        if dt <= self.config.gate_velocity_max_dt \
                and math.degrees(turn) / dt >= self.config.gate_fast_turn_deg_s:
            self.idle, self.idle_t, self.travel = True, t, 0.0
        self._sample(t, pose)

    def _reason(self, t, pose):
        cfg = self.config
        if self.idle:
            rested = t - self.idle_t >= cfg.gate_recovery_time - TIME_TOLERANCE
            if rested and self.travel >= cfg.gate_recovery_distance:
                self.idle = False
            else:
                return GATED_FAST_TURN
        if t - self.proc_t < cfg.gate_min_interval - TIME_TOLERANCE:
            return GATED_INTERVAL
        moved = math.hypot(pose.x - self.proc_x, pose.y - self.proc_y) >= cfg.gate_min_distance
        turn = math.degrees(abs(wrap_angle(pose.theta - self.proc_th)))
        turned = turn >= cfg.gate_min_rotation_deg
        self._by_turn = turned and not moved
        if self._by_turn and cfg.gate_turn_cover:
            views = self._counted()
            if min(views[k] for k in self._seen(*self._view)) >= cfg.gate_turn_views:
                return GATED_TURN_VIEWS
        return "" if moved or turned else GATED_NO_MOTION

    # --- saving and restoring -----------------------------------------------------------------
    def state(self) -> dict:
        out = {name: getattr(self, name) for name in _FIELDS}
        return out | {"turn_views": [int(v) for v in self.turn_views]}

    def restore(self, state: dict) -> None:
        # states saved before the per-direction rule have none: no view counted yet
        state = {"turn_views": [0] * DIRECTION_BINS, **state}
        missing = [name for name in _FIELDS if name not in state]
        if missing:
            raise ValueError(f"gate state lacks {missing}")
        for name in _FIELDS:
            value = state[name]
            if name == "turn_views":
                value = np.asarray(value, np.int64)
            elif name not in ("source", "idle"):
                value = float(value)
            setattr(self, name, value)
