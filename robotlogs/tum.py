"""Trajectories in the TUM format (``t x y z qx qy qz qw``), which evo and most SLAM
evaluation tools read."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from gridmap.atomic import write_atomically


def write_tum(path: Path, time: np.ndarray, poses: np.ndarray) -> None:
    """Write planar ``poses`` (N, 3) at ``time`` (N,) with z = 0 and the yaw as a quaternion,
    atomically."""
    lines = [f"{t:.6f} {p[0]:.6f} {p[1]:.6f} 0 0 0 {math.sin(p[2] / 2):.9f} "
             f"{math.cos(p[2] / 2):.9f}" for t, p in zip(time, poses)]
    write_atomically(path, "\n".join(lines) + ("\n" if lines else ""))
