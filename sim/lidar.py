"""Simulated 2D lidars: beams cast exactly against the world's segments and circles.

One kernel call casts a whole scan (or many scans); this module composes the sensor poses,
adds the range noise and packs ``gridmap.Scan`` objects.
"""

from __future__ import annotations

import numpy as np

from gridmap import Pose2D, Scan


def _kernels():
    from . import _kernels  # numba is imported lazily so that importing sim stays fast

    return _kernels


def sensor_poses(robot_poses: np.ndarray, mount: Pose2D) -> np.ndarray:
    """Sensor poses (N, 3) in the map frame: each robot pose (N, 3) composed with the mount."""
    p = np.asarray(robot_poses, np.float64).reshape(-1, 3)
    c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
    out = np.empty_like(p)
    out[:, 0] = p[:, 0] + c * mount.x - s * mount.y
    out[:, 1] = p[:, 1] + s * mount.x + c * mount.y
    out[:, 2] = (p[:, 2] + mount.theta + np.pi) % (2 * np.pi) - np.pi
    return out


def cast_ranges(sensors: np.ndarray, spec, segments: np.ndarray, circles: np.ndarray) -> np.ndarray:
    """Exact ranges [m] (N, beams), float64, of the lidar ``spec`` (a ``LidarSpec``) from sensor
    poses (N, 3) to the first segment (M, 4; outlines of counter-clockwise polygons) or circle
    (K, 3) hit; inf where nothing is within range_max."""
    sensors = np.ascontiguousarray(sensors, np.float64).reshape(-1, 3)
    out = np.empty((sensors.shape[0], spec.beams), np.float64)
    _kernels().cast_scans(sensors, angle_min=spec.angle_min, inc=spec.angle_increment,
                          segs=np.ascontiguousarray(segments, np.float64).reshape(-1, 4),
                          circles=np.ascontiguousarray(circles, np.float64).reshape(-1, 3),
                          max_range=spec.range_max, out=out)
    return out


def measure(ranges: np.ndarray, spec, rng: np.random.Generator | None) -> np.ndarray:
    """What the lidar reports for exact ``ranges``: Gaussian range noise (none without ``rng``),
    inf for no return and for readings beyond range_max, as float32."""
    r = np.array(ranges, np.float64)
    if rng is not None and spec.range_noise_std > 0:
        # one draw per beam, returns or not, so the stream does not depend on the scene
        r += rng.normal(0.0, spec.range_noise_std, r.shape)
    r[~(r <= spec.range_max)] = np.inf
    return r.astype(np.float32)


def make_scan(ranges: np.ndarray, spec, time: float) -> Scan:
    """A scan of ``spec`` as a ``sensor_msgs/LaserScan`` carries it: its angles and range limits
    are float32 fields there, so a run and its recording played back see the same beams (with
    the float64 angles, a session of a hundred played back from bags differed by a cell)."""
    return Scan(ranges, *(float(np.float32(v)) for v in (spec.angle_min, spec.angle_increment,
                                                          spec.range_min, spec.range_max)),
                float(time))
