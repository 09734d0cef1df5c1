"""The odometry motion model of a differential drive (Probabilistic Robotics, table 5.6).

As in nav2's DifferentialMotionModel: the step between two odometry poses is split into a
rotation, a translation and a rotation; noise variances grow with alpha1..alpha4; and backward
motion is treated like forward motion for the noise (a reversing robot's rot1 is near pi, which
must not read as a large turn). The step and the size of a turn are ``gridmap.motion``'s, the
same the simulator's odometry uses.
"""

from __future__ import annotations

import numpy as np

from gridmap import Pose2D
from gridmap.motion import odometry_delta, turn_for_noise

__all__ = ["motion_sigmas", "odometry_delta", "sample_motion"]


def _kernels():
    from . import _kernels  # numba is imported lazily so that importing the package stays fast

    return _kernels


def motion_sigmas(delta, alphas) -> np.ndarray:
    """Standard deviations of (rot1, trans, rot2) for one odometry step."""
    rot1, trans, rot2 = delta
    a1, a2, a3, a4 = alphas
    r1, r2 = turn_for_noise(rot1), turn_for_noise(rot2)
    # The simulator's sim.odometry.motion_sigmas sums the turns before scaling them; the two
    # forms round differently in the last bit, and each is kept so that recorded results stay
    # bit for bit the same (see there).
    return np.sqrt([a1 * r1 * r1 + a2 * trans * trans,
                    a3 * trans * trans + a4 * r1 * r1 + a4 * r2 * r2,
                    a1 * r2 * r2 + a2 * trans * trans])


def sample_motion(poses: np.ndarray, previous: Pose2D, current: Pose2D, alphas,
                  rng: np.random.Generator, noise: np.ndarray | None = None) -> None:
    """sample_motion_model_odometry: move ``poses`` (N, 3, float64) in place by the odometry
    step ``previous`` -> ``current``, each with its own noise drawn from ``rng`` (into
    ``noise``, an (N, 3) float64 buffer, when given: the very numbers a fresh array would get)."""
    delta = odometry_delta(previous, current)
    if noise is None:
        noise = rng.standard_normal((poses.shape[0], 3))
    else:
        rng.standard_normal(out=noise)
    _kernels().sample_motion_odometry(poses, np.array(delta), motion_sigmas(delta, alphas), noise)
