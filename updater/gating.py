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
"""

from __future__ import annotations

import math

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
           "proc_th", "idle", "idle_t", "travel", "turn_swept")


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
        self.turn_swept = 0.0      # [deg] turned by scans processed for turning alone, since
                                   # the last one processed for moving
        self._by_turn = False      # the scan just let through was for turning alone ...
        self._turn = 0.0           # [deg] ... by this much since the last processed

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
        if math.isnan(self.proc_t):
            return ""
        return self._reason(t, pose, fov_deg)

    def mark_processed(self, t: float, pose: Pose2D) -> None:
        self.proc_t, self.proc_x, self.proc_y, self.proc_th = t, pose.x, pose.y, pose.theta
        self.turn_swept = self.turn_swept + self._turn if self._by_turn else 0.0

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

    def _reason(self, t, pose, fov_deg):
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
        self._by_turn, self._turn = turned and not moved, turn
        circle = 360.0 - min(fov_deg, 360.0) + cfg.gate_min_rotation_deg
        if self._by_turn and cfg.gate_turn_cover and self.turn_swept + turn > circle:
            return GATED_TURN_VIEWS
        return "" if moved or turned else GATED_NO_MOTION

    # --- saving and restoring -----------------------------------------------------------------
    def state(self) -> dict:
        return {name: getattr(self, name) for name in _FIELDS}

    def restore(self, state: dict) -> None:
        state = {"turn_swept": 0.0, **state}     # states saved before the rule had none
        missing = [name for name in _FIELDS if name not in state]
        if missing:
            raise ValueError(f"gate state lacks {missing}")
        for name in _FIELDS:
            value = state[name]
            setattr(self, name, value if name in ("source", "idle") else float(value))
