"""Wheel odometry that drifts: the odometry motion model of Probabilistic Robotics (table 5.6),
with the variances of AMCL's / nav2's differential model (``gridmap.motion``, which the
localiser's model shares), applied once per odometry message.

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
from gridmap.motion import MIN_TRANS_FOR_BEARING, odometry_delta, turn_for_noise

__all__ = ["MIN_TRANS_FOR_BEARING", "Odometry", "apply_delta", "motion_sigmas", "noisy_step",
           "odometry_delta"]


def motion_sigmas(delta, alphas) -> np.ndarray:
    """Standard deviations of the noise on (rot1, trans, rot2) for one increment; a reversing
    step (rot1 near pi) counts as a small turn, as in AMCL."""
    rot1, trans, rot2 = delta
    a1, a2, a3, a4 = alphas
    r1, r2 = turn_for_noise(rot1), turn_for_noise(rot2)
    # The same variances as localization.motion.motion_sigmas, but the translation's sums its
    # turns before scaling them (alpha4 * (r1^2 + r2^2)) where the filter's scales each
    # (alpha4 * r1^2 + alpha4 * r2^2). The two round differently in the last bit in about one
    # step in six; each is kept as it was so that the world's odometry and the filter's draws,
    # and with them every recorded result, stay bit for bit the same.
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
