"""The pose estimate: the weighted mean of the heaviest particle cluster, with its covariance.

Clusters are AMCL's: particles fall into the KLD histogram's bins (0.5 m x 0.5 m x 10 deg),
and bins that touch (26-neighbourhood, heading wrapping around) form one cluster. AMCL finds
them through its kd-tree; here a hash set of the occupied bins, a look-up per neighbour and a
union-find do it, in one kernel that also sums each cluster's weight.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gridmap import Pose2D, wrap_angle

from .resample import KldParameters, Scratch, hash_table


def _kernels():
    from . import _kernels

    return _kernels


@dataclass(frozen=True)
class Estimate:
    """Where the robot is: ``pose`` with covariance ``cov`` (x, y, theta) [m^2, rad^2], and the
    map -> odom transform as ``correction_pose`` (the estimate at the latest correction) and
    ``correction_odom`` (the odometry pose it was made at)."""

    pose: Pose2D
    cov: np.ndarray
    correction_pose: Pose2D
    correction_odom: Pose2D
    cluster_weight: float = 1.0      # share of the particle weight in the chosen cluster

    def map_to_odom(self) -> Pose2D:
        return self.correction_pose.compose(self.correction_odom.inverse())

    def pose_at(self, odom_pose: Pose2D) -> Pose2D:
        """The robot's pose in the map at ``odom_pose``: the latest correction composed with the
        odometry since then (ROS's map -> odom convention)."""
        return self.correction_pose.compose(odom_pose.relative_to(self.correction_odom))


def cluster_labels(poses: np.ndarray, kld: KldParameters) -> tuple[np.ndarray, int]:
    """Cluster index (N,) of each pose and the number of clusters."""
    labels, share, _ = _clusters(poses, np.zeros(poses.shape[0]), kld, None)
    return labels, int(share.size)


def _clusters(poses, weights, kld, scratch):
    """(labels (N,), summed weight per cluster, particle count per cluster)."""
    labels = np.empty(poses.shape[0], np.int64)
    share, counts = _kernels().cluster_particles(
        poses, weights, kld.bin_size, kld.n_theta, hash_table(poses.shape[0], scratch), labels)
    return labels, share, counts


def weighted_mean_cov(poses: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean (circular in theta) and covariance of weighted poses; theta deviations are taken
    from the mean heading, wrapped, so a cluster across +-pi is not torn apart."""
    w = weights / weights.sum()
    theta = math.atan2(float(w @ np.sin(poses[:, 2])), float(w @ np.cos(poses[:, 2])))
    mean = np.array([w @ poses[:, 0], w @ poses[:, 1], theta])
    if poses.dtype != np.float64 or w.dtype != np.float64:
        d = poses - mean
        d[:, 2] = wrap_angle(d[:, 2])
        return mean, (d * w[:, None]).T @ d
    # the deviations in one kernel pass, then the same matrix product on the same arrays
    d, dw = np.empty(poses.shape), np.empty(poses.shape)
    _kernels().centred(poses, mean, w, d, dw)
    return mean, dw.T @ d


def estimate(poses: np.ndarray, weights: np.ndarray, kld: KldParameters,
             scratch: Scratch | None = None):
    """(mean (3,), cov (3, 3), weight share) of the heaviest cluster of particles."""
    labels, share, counts = _clusters(poses, weights, kld, scratch)
    best = int(np.argmax(share))
    if share.size == 1 and poses.flags.c_contiguous and weights.flags.c_contiguous:
        sel_poses, sel_weights = poses, weights        # the copy a selection would make
    else:
        sel_poses = np.empty((counts[best], 3), poses.dtype)
        sel_weights = np.empty(counts[best], weights.dtype)
        _kernels().take_label(poses, weights, labels, best, sel_poses, sel_weights)
    mean, cov = weighted_mean_cov(sel_poses, sel_weights)
    return mean, cov, float(share[best] / share.sum())
