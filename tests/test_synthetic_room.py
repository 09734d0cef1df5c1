"""The synthetic-room helpers of the updater's tests, checked against plain geometry."""

import math

import numpy as np

from gridmap import FREE, OCCUPIED, UNKNOWN, Pose2D
from synthetic_room import Circle, Rect, cast, cells_of, rasterise


def test_cast_matches_geometry():
    shapes = [Rect(2.0, 1.0, 3.0, 4.0), Circle(0.0, 5.0, 1.0)]
    pose = Pose2D(0.0, 2.0, 0.0)
    r = cast(shapes, pose, np.array([0.0, math.pi / 2, math.pi, math.atan2(2.0, 2.0)]), 10.0)
    assert r[0] == 2.0                                 # face x = 2
    assert abs(r[1] - 2.0) < 1e-12                     # circle bottom at y = 4
    assert r[2] == np.inf
    assert abs(r[3] - math.hypot(2.0, 2.0)) < 1e-12    # corner (2, 4)


def test_rasterise_outline_and_interior():
    box = Rect(3.02, 3.02, 4.03, 3.61)
    grid = rasterise([], hollow=[box])
    m = cells_of(box)
    assert m.sum() == 21 * 13                          # columns 60..80, rows 60..72
    inside = grid.data[m]
    assert (inside == UNKNOWN).sum() == 19 * 11 and (inside == OCCUPIED).sum() == 21 * 13 - 209
    assert grid.data[0, 0] == UNKNOWN and grid.data[110, 110] == FREE


