"""Wheel odometry that drifts: the odometry motion model of Probabilistic Robotics (table 5.6),
with the variances of AMCL's / nav2's differential model, applied once per odometry message.

Each message's true increment (rot1, trans, rot2) is corrupted with Gaussian noise of variance

    rot1:  alpha1 * rot1^2 + alpha2 * trans^2
    trans: alpha3 * trans^2 + alpha4 * (rot1^2 + rot2^2)
    rot2:  alpha1 * rot2^2 + alpha2 * trans^2

and the noisy increment is chained onto the previous odometry pose. The variances grow with the
square of the increment, so the drift over a route depends on the message rate: the noise must be
applied per message, never per physics step (tiny steps would make the drift vanish).
"""

from __future__ import annotations

import math

import numpy as np

from gridmap import Pose2D, wrap_angle

# Below this translation [m] the bearing of the step is noise: rot1 = 0, as AMCL and nav2 do.
MIN_TRANS_FOR_BEARING = 0.01


def odometry_delta(previous: Pose2D, current: Pose2D) -> tuple[float, float, float]:
    """(rot1 [rad], trans [m], rot2 [rad]) that take ``previous`` to ``current``."""
    dx, dy = current.x - previous.x, current.y - previous.y
    trans = math.hypot(dx, dy)
    rot1 = 0.0 if trans < MIN_TRANS_FOR_BEARING else wrap_angle(math.atan2(dy, dx) - previous.theta)
    rot2 = wrap_angle(current.theta - previous.theta - rot1)
    return rot1, trans, rot2


def motion_sigmas(delta, alphas) -> np.ndarray:
    """Standard deviations of the noise on (rot1, trans, rot2) for one increment; a reversing
    step (rot1 near pi) counts as a small turn, as in AMCL."""
    rot1, trans, rot2 = delta
    a1, a2, a3, a4 = alphas
    r1 = min(abs(wrap_angle(rot1)), abs(wrap_angle(rot1 - math.pi)))
    r2 = min(abs(wrap_angle(rot2)), abs(wrap_angle(rot2 - math.pi)))
    return np.sqrt([a1 * r1 * r1 + a2 * trans * trans,
                    a3 * trans * trans + a4 * (r1 * r1 + r2 * r2),
                    a1 * r2 * r2 + a2 * trans * trans])


def apply_delta(pose: Pose2D, delta) -> Pose2D:
    """``pose`` moved by (rot1, trans, rot2)."""
    rot1, trans, rot2 = delta
    heading = pose.theta + rot1
    return Pose2D(pose.x + trans * math.cos(heading), pose.y + trans * math.sin(heading),
                  wrap_angle(heading + rot2))


def noisy_step(odom: Pose2D, true_previous: Pose2D, true_current: Pose2D, alphas,
               noise: np.ndarray) -> Pose2D:
    """The next odometry pose: ``odom`` moved by the true increment corrupted with ``noise``
    (three standard normal draws, scaled here by ``motion_sigmas``)."""
    delta = odometry_delta(true_previous, true_current)
    sig = motion_sigmas(delta, alphas)
    noisy = (float(delta[0] + sig[0] * noise[0]), float(delta[1] + sig[1] * noise[1]),
             float(delta[2] + sig[2] * noise[2]))
    return apply_delta(odom, noisy)


class Odometry:
    """The odometry of one robot: an odom frame that starts at the true start pose and drifts.

    ``tick`` is called at each odometry message time with the true pose; ``pose_at`` gives the
    odometry pose at a time between ticks (a scan) by adding the true motion since the last tick,
    so the noise stays a property of the messages alone."""

    def __init__(self, start: Pose2D, alphas, rng: np.random.Generator):
        self.alphas = tuple(float(a) for a in alphas)
        self.rng = rng
        self.last_true = start
        self.pose = start

    def tick(self, true_pose: Pose2D) -> Pose2D:
        if true_pose == self.last_true:
            return self.pose        # standing still: wheels report no motion, and no noise
        noise = self.rng.standard_normal(3)
        self.pose = noisy_step(self.pose, self.last_true, true_pose, self.alphas, noise)
        self.last_true = true_pose
        return self.pose

    def pose_at(self, true_pose: Pose2D) -> Pose2D:
        if true_pose == self.last_true:
            return self.pose
        return self.pose.compose(true_pose.relative_to(self.last_true))
