"""The odometry motion model of a differential drive (Probabilistic Robotics, table 5.6, with the
choices of nav2's DifferentialMotionModel): the step between two poses as a rotation, a
translation and a rotation, and the size of a turn for its noise.

Both the simulator's drifting odometry (``sim.odometry``, the world's noise) and the localiser's
motion update (``localization.motion``, the filter's model of that noise) use these, so the
filter models exactly the increments the world corrupts. The noise variances grow with
alpha1..alpha4 as

    rot1:  alpha1 * rot1^2 + alpha2 * trans^2
    trans: alpha3 * trans^2 + alpha4 * (rot1^2 + rot2^2)
    rot2:  alpha1 * rot2^2 + alpha2 * trans^2

with each turn measured by ``turn_for_noise``; each package writes these three lines itself
(see its ``motion_sigmas``).
"""

from __future__ import annotations

import math

from .types import Pose2D, wrap_angle

# Below this translation [m] the bearing of the step is noise (a turn in place): rot1 = 0, as
# AMCL and nav2 do.
MIN_TRANS_FOR_BEARING = 0.01


def odometry_delta(previous: Pose2D, current: Pose2D) -> tuple[float, float, float]:
    """(rot1 [rad], trans [m], rot2 [rad]) that take ``previous`` to ``current``."""
    dx, dy = current.x - previous.x, current.y - previous.y
    trans = math.hypot(dx, dy)
    rot1 = 0.0 if trans < MIN_TRANS_FOR_BEARING else wrap_angle(math.atan2(dy, dx) - previous.theta)
    rot2 = wrap_angle(current.theta - previous.theta - rot1)
    return rot1, trans, rot2


def turn_for_noise(rot: float) -> float:
    """The size [rad] of a turn for the noise: a reversing step's rot1 lies near pi, which must
    not read as a large turn, so backward motion counts like forward motion (as in AMCL)."""
    return min(abs(wrap_angle(rot)), abs(wrap_angle(rot - math.pi)))
