"""The pose estimate: the weighted mean of the heaviest particle cluster, with its covariance.

Clusters are AMCL's: particles fall into the KLD histogram's bins (0.5 m x 0.5 m x 10 deg),
and bins that touch (26-neighbourhood, heading wrapping around) form one cluster. AMCL finds
them through its kd-tree; here a sort, a binary search per neighbour and a union-find do it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gridmap import Pose2D, wrap_angle

from .resample import KldParameters, histogram_keys


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
    labels = np.empty(poses.shape[0], np.int64)
    count = _kernels().cluster_bins(histogram_keys(poses, kld), kld.n_theta, labels)
    return labels, int(count)


def weighted_mean_cov(poses: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean (circular in theta) and covariance of weighted poses; theta deviations are taken
    from the mean heading, wrapped, so a cluster across +-pi is not torn apart."""
    w = weights / weights.sum()
    theta = math.atan2(float(w @ np.sin(poses[:, 2])), float(w @ np.cos(poses[:, 2])))
    mean = np.array([w @ poses[:, 0], w @ poses[:, 1], theta])
    d = poses - mean
    d[:, 2] = wrap_angle(d[:, 2])
    cov = (d * w[:, None]).T @ d
    return mean, cov


def estimate(poses: np.ndarray, weights: np.ndarray, kld: KldParameters):
    """(mean (3,), cov (3, 3), weight share) of the heaviest cluster of particles."""
    labels, count = cluster_labels(poses, kld)
    share = np.bincount(labels, weights=weights, minlength=count)
    best = int(np.argmax(share))
    sel = labels == best
    mean, cov = weighted_mean_cov(poses[sel], weights[sel])
    return mean, cov, float(share[best] / share.sum())
