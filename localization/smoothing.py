"""A recorded localisation smoothed with the odometry: what the map updater is given when the
robot's map-frame pose comes from elsewhere (amcl's ``map -> odom`` in a bag or on a live robot,
a log's corrected poses) rather than from this project's localiser.

A localisation jitters from scan to scan: each filter update moves ``map -> odom`` by a few
centimetres and a fraction of a degree, while wheel odometry is smooth over a few metres. At
2 cm and 0.5 deg of jitter a face the updater should draw no longer collects 7 changed flags
of 10 in one cell (a synthetic hall, tests/test_logs_jitter.py: 0.79-0.91 of the added
objects' outlines drawn, 0.99-1.00 once smoothed).

``PoseSmoother(window)`` is called once per scan, in time order, with the recorded pose and the
odometry at the scan. Each recorded pose of the last ``window`` seconds, carried to this scan by
the odometry since it (``recorded_j (+) (odom_j^-1 (+) odom_k)``), predicts the pose now; the
mean of the predictions (the circular mean for the heading) is the pose used. Only past scans
count, so a live robot does the same; at most ``MAX_POSES`` of them, the latest, so that
stamps which do not advance cost no more per scan than a full window. A recorded pose farther
than ``jump`` metres or ``jump_deg`` degrees from the window's prediction is a relocalisation,
not jitter: the window starts again from it, so a corrected pose is used at once rather than
blended in over the window.

Only a localisation that jitters is smoothed, judged on the window's own poses, each recorded
pose against an earlier one carried by the odometry (the innovation):

- It moves against the odometry at most scans (``JITTER_SHARE``). amcl corrects
  ``map -> odom`` only at its filter updates (every 0.2 m by default), so between them its
  poses follow the odometry exactly, and each update is a correction of the drift since the
  last; averaging those would only hold the corrections back (the simulated warehouse's bags,
  whose localiser works so, lose precision and recall in W2 when smoothed; figures in
  benchmarks/RESULTS.md).
- Its innovations do not grow with the lag (``MAX_GROWTH``). Jitter is fresh at every scan,
  so a pose half a window back differs from the latest by no more than the previous one does;
  odometry noise adds up, so with a precise localisation and noisy odometry the innovation
  grows with the lag, and carrying old poses over it would add the odometry's error.

A pose or odometry that is not finite is passed on as it is and kept out of the window.
"""

from __future__ import annotations

import math

import numpy as np

from gridmap import Pose2D

from .config import LocalizationError

# The default window [s]: 20 scans at 10 Hz cut 2 cm / 0.5 deg of jitter to about 0.5 cm /
# 0.1 deg, while wheel odometry drifts by well under a centimetre over it.
SMOOTH_WINDOW = 2.0
MAX_WINDOW = 60.0
JUMP = 0.25             # [m] a recorded pose this far from the prediction restarts the window
JUMP_DEG = 5.0          # [deg] ... or turned this much
JITTER_SHARE = 0.5      # smooth only when at least this share of the window's scans moved
MOVED = 1e-4            # [m, rad] a recorded pose this far from the last one carried by the
                        # odometry moved against it (float rounding stays far below)
MAX_GROWTH = 3.0        # ... and the mean squared innovation at half the window's length is
                        # at most this many times the one at one scan
MIN_POSES = 8           # poses in the window before any is smoothed
# The most poses the window keeps, whatever its length: stamps that do not advance (a bag or a
# driver that repeats one stamp) never empty a window of seconds, and each scan's work grows
# with the window (3000 scans at one stamp took 55 s, quadratic). 128 predictions already cut
# the jitter 11-fold; older poses only add the odometry's drift. The default window holds
# fewer at any lidar rate up to 64 Hz (20 at 10 Hz).
MAX_POSES = 128


class PoseSmoother:
    """Recorded map-frame poses smoothed with the odometry over the last ``window`` seconds
    (0: the recorded pose as it is). See the module docstring."""

    def __init__(self, window: float = SMOOTH_WINDOW, jump: float = JUMP,
                 jump_deg: float = JUMP_DEG):
        for name, value, top in (("window", window, MAX_WINDOW), ("jump", jump, 100.0),
                                 ("jump_deg", jump_deg, 180.0)):
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not 0 <= value <= top:
                raise LocalizationError(f"pose smoothing: {name} must be a number in "
                                        f"[0, {top:g}], got {value!r}")
        self.window, self.jump, self.jump_deg = float(window), float(jump), float(jump_deg)
        # (time, recorded, odometry, innovation against the previous record, or None)
        self._past: list = []
        self.restarts = 0              # windows restarted by a jump of the localisation
        self.smoothed = 0              # scans whose pose was smoothed

    def __call__(self, time: float, recorded: Pose2D | None, odom: Pose2D | None):
        """The pose to use at a scan at ``time`` [s]; the recorded pose as it is when either
        pose is missing or the window is 0."""
        if recorded is None or odom is None or not self.window > 0 or \
                not (recorded.is_finite() and odom.is_finite() and math.isfinite(time)):
            return recorded
        self._past = [p for p in self._past
                      if time - self.window < p[0] <= time][-(MAX_POSES - 1):]
        step = _innovation(self._past[-1], recorded, odom) if self._past else None
        if self._past and self._jumped(self._predict(odom), recorded):
            self._past = []
            self.restarts += 1
        self._past.append((time, recorded, odom, step))
        if not self._jitters():
            return recorded
        self.smoothed += 1
        return self._predict(odom)

    def _jitters(self) -> bool:
        """Whether the window's poses jitter against the odometry (module docstring)."""
        past = self._past
        n = len(past)
        moved = sum(p[3] is not None and _moved(p[3]) for p in past)
        if n < MIN_POSES or moved < JITTER_SHARE * n:
            return False
        near = [p[3] for p in past[1:]]        # each against the one before it
        lag = n // 2
        far = [_innovation(past[i], past[i + lag][1], past[i + lag][2]) for i in range(n - lag)]
        for k in (0, 1):        # position [m^2], heading [rad^2]
            one = float(np.mean([d[k] for d in near]))
            if one > 0 and float(np.mean([d[k] for d in far])) > MAX_GROWTH * one:
                return False
        return True

    def _predict(self, odom: Pose2D) -> Pose2D:
        guesses = np.array([p[1].compose(odom.relative_to(p[2])).as_array()
                            for p in self._past])
        yaw = math.atan2(np.sin(guesses[:, 2]).mean(), np.cos(guesses[:, 2]).mean())
        return Pose2D(float(guesses[:, 0].mean()), float(guesses[:, 1].mean()), yaw)

    def _jumped(self, predicted: Pose2D, recorded: Pose2D) -> bool:
        off = recorded.relative_to(predicted)
        return math.hypot(off.x, off.y) > self.jump or \
            abs(math.degrees(off.theta)) > self.jump_deg


def _innovation(past, recorded: Pose2D, odom: Pose2D) -> tuple[float, float]:
    """(squared distance [m^2], squared turn [rad^2]) of ``recorded`` from the ``past``
    (time, recorded, odometry, ...) record's pose carried to it by the odometry."""
    off = recorded.relative_to(past[1].compose(odom.relative_to(past[2])))
    return off.x * off.x + off.y * off.y, off.theta * off.theta


def _moved(innovation: tuple[float, float]) -> bool:
    return innovation[0] > MOVED * MOVED or innovation[1] > MOVED * MOVED
