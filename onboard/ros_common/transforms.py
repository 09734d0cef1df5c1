"""3D transforms as a planar robot needs them: a quaternion checked as tf2 checks it, and a
rotation reduced to the plane, with the one thing a 2D pose cannot say: whether the frame is
upside down. A lidar mounted under a plate (roll = pi) sweeps the other way round; read as
upright, its scan would be mirrored about its x axis and the map drawn wrong.

Poses in the plane that may be mirrored are 3 x 3 matrices ``[[a, b, x], [c, d, y], [0, 0, 1]]``
whose 2 x 2 block is a rotation (upright) or a rotation times ``diag(1, -1)`` (upside down):
they compose by matrix product, exactly as the 3D transforms they come from when every
rotation on the way turns about z or flips z over. No ROS import."""

from __future__ import annotations

import math

import numpy as np

from gridmap import MapUpdatingError, Pose2D, Scan

# tf2 (BufferCore::setTransform) ignores a transform whose quaternion's squared norm is this
# far from 1, and normalises the others
QUATERNION_TOLERANCE = 0.01


class TransformError(MapUpdatingError, ValueError):
    """A transform a planar robot cannot use; the message says why."""


def unit_quaternion(x: float, y: float, z: float, w: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) normalised; ``TransformError`` when its squared norm is more than
    ``QUATERNION_TOLERANCE`` away from 1 (a zero quaternion too), as tf2 refuses it."""
    n2 = x * x + y * y + z * z + w * w
    if not (math.isfinite(n2) and abs(n2 - 1.0) <= QUATERNION_TOLERANCE):
        raise TransformError(f"quaternion ({x:g}, {y:g}, {z:g}, {w:g}) is not unit (norm "
                             f"{math.sqrt(n2) if math.isfinite(n2) else n2:g})")
    n = math.sqrt(n2)
    return x / n, y / n, z / n, w / n


def planar(tx: float, ty: float, q) -> tuple[Pose2D, bool, float]:
    """(pose in the plane, upside down, tilt [rad]) of a transform with translation (tx, ty, .)
    and unit quaternion ``q`` (x, y, z, w): the yaw is the direction the frame's x axis points
    in; upside down when its z axis points down; the tilt is the angle between its z axis and
    the vertical line (0 for upright and upside-down frames alike)."""
    x, y, z, w = q
    r00, r10 = 1 - 2 * (y * y + z * z), 2 * (x * y + w * z)
    r22 = 1 - 2 * (x * x + y * y)
    tilt = math.acos(min(1.0, abs(r22)))
    return Pose2D(float(tx), float(ty), math.atan2(r10, r00)), r22 < 0, tilt


def matrix(pose: Pose2D, flipped: bool = False) -> np.ndarray:
    """The 3 x 3 matrix of a pose in the plane, mirrored about its x axis when ``flipped``."""
    c, s = math.cos(pose.theta), math.sin(pose.theta)
    m = np.array([[c, -s, pose.x], [s, c, pose.y], [0.0, 0.0, 1.0]])
    if flipped:
        m[:2, 1] *= -1.0
    return m


def from_matrix(m: np.ndarray) -> tuple[Pose2D, bool]:
    """(pose, upside down) of a matrix made by ``matrix`` and products of such."""
    return Pose2D(float(m[0, 2]), float(m[1, 2]), math.atan2(m[1, 0], m[0, 0])), \
        bool(np.linalg.det(m[:2, :2]) < 0)


def mirrored(scan: Scan) -> Scan:
    """The scan of an upside-down lidar as an upright one at the same yaw sees it: each beam at
    angle a in the lidar's frame lies at -a. Negation is exact, so mirroring twice gives the
    same scan bit for bit."""
    return Scan(scan.ranges, -scan.angle_min, -scan.angle_increment, scan.range_min,
                scan.range_max, scan.time)


def ascending(scan: Scan) -> Scan:
    """The scan with its beams in counter-clockwise order: a lidar that sweeps clockwise (a
    negative ``angle_increment``, which ROS allows) gives the same beams, reversed."""
    if scan.angle_increment > 0:
        return scan
    last = scan.angle_min + (scan.beams - 1) * scan.angle_increment
    return Scan(scan.ranges[::-1].copy(), last, -scan.angle_increment, scan.range_min,
                scan.range_max, scan.time)
