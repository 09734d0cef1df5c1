"""The odometry motion model of a differential drive (Probabilistic Robotics, table 5.6).

As in nav2's DifferentialMotionModel: the step between two odometry poses is split into a
rotation, a translation and a rotation; noise variances grow with alpha1..alpha4; and backward
motion is treated like forward motion for the noise (a reversing robot's rot1 is near pi, which
must not read as a large turn).
"""

from __future__ import annotations

import math

import numpy as np

from gridmap import Pose2D, wrap_angle


def _kernels():
    from . import _kernels  # numba is imported lazily so that importing the package stays fast

    return _kernels


def odometry_delta(previous: Pose2D, current: Pose2D) -> tuple[float, float, float]:
    """(rot1 [rad], trans [m], rot2 [rad]) that take ``previous`` to ``current``."""
    dx, dy = current.x - previous.x, current.y - previous.y
    trans = math.hypot(dx, dy)
    # A bearing between two nearly equal positions is noise (in-place rotation): nav2 sets it 0.
    rot1 = 0.0 if trans < 0.01 else wrap_angle(math.atan2(dy, dx) - previous.theta)
    rot2 = wrap_angle(current.theta - previous.theta - rot1)
    return rot1, trans, rot2


def motion_sigmas(delta, alphas) -> np.ndarray:
    """Standard deviations of (rot1, trans, rot2) for one odometry step."""
    rot1, trans, rot2 = delta
    a1, a2, a3, a4 = alphas
    r1 = min(abs(wrap_angle(rot1)), abs(wrap_angle(rot1 - math.pi)))
    r2 = min(abs(wrap_angle(rot2)), abs(wrap_angle(rot2 - math.pi)))
    return np.sqrt([a1 * r1 * r1 + a2 * trans * trans,
                    a3 * trans * trans + a4 * r1 * r1 + a4 * r2 * r2,
                    a1 * r2 * r2 + a2 * trans * trans])


def sample_motion(poses: np.ndarray, previous: Pose2D, current: Pose2D, alphas,
                  rng: np.random.Generator) -> None:
    """sample_motion_model_odometry: move ``poses`` (N, 3, float64) in place by the odometry
    step ``previous`` -> ``current``, each with its own noise drawn from ``rng``."""
    delta = odometry_delta(previous, current)
    noise = rng.standard_normal((poses.shape[0], 3))
    _kernels().sample_motion_odometry(poses, np.array(delta), motion_sigmas(delta, alphas), noise)
