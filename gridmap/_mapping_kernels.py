"""numba kernel of log-odds occupancy mapping. Arrays in, arrays out, grid units throughout."""

import numpy as np
from numba import njit

from ._kernels import traverse


@njit(cache=True)
def integrate_scan(logodds, stamp, scan_id, sensor, angles, ranges, limits, increments,
                   rows, cols):
    """Add one scan to ``logodds`` (float32, rows x cols) in place.

    sensor = (gx, gy) of the sensor; angles [rad] in the grid frame; ranges in grid units
    (inf for no return); limits = (range_min, range_max, clearance, guard) in grid units,
    guard a whole number of cells; increments = (hit, miss, clamp_min, clamp_max).
    ``rows``/``cols`` are scratch buffers at least as long as the longest traversal.

    Each cell changes at most once per scan (``stamp`` remembers which cells ``scan_id``
    touched) and hits go first, so beams grazing past a wall cell cannot cancel the beam that
    hit it, and cells near the sensor do not gain one miss per beam. With guard g > 0 the
    cells within g cells (Chebyshev) of a return get no miss from the same scan either."""
    h, w = logodds.shape
    gx, gy = sensor[0], sensor[1]
    r_min, r_max, clearance = limits[0], limits[1], limits[2]
    guard = int(limits[3])
    hit, miss, lo, hi = increments[0], increments[1], increments[2], increments[3]
    for i in range(angles.shape[0]):
        r = ranges[i]
        if r >= r_min and r < r_max:  # false for nan and inf
            col = int(np.floor(gx + r * np.cos(angles[i])))
            row = int(np.floor(gy + r * np.sin(angles[i])))
            if 0 <= row < h and 0 <= col < w and stamp[row, col] != scan_id:
                logodds[row, col] = min(logodds[row, col] + hit, hi)
                stamp[row, col] = scan_id
    if guard > 0:
        for i in range(angles.shape[0]):
            r = ranges[i]
            if r >= r_min and r < r_max:
                col = int(np.floor(gx + r * np.cos(angles[i])))
                row = int(np.floor(gy + r * np.sin(angles[i])))
                for rr in range(max(row - guard, 0), min(row + guard + 1, h)):
                    for cc in range(max(col - guard, 0), min(col + guard + 1, w)):
                        stamp[rr, cc] = scan_id
    for i in range(angles.shape[0]):
        r = ranges[i]
        if r >= r_min and r < r_max:
            length = r
        elif r >= r_max:
            # No return: space is free up to the clearance, but nothing was hit.
            length = min(clearance, r_max)
        else:
            continue  # below range_min or nan: an invalid reading says nothing
        n = traverse(gx, gy, gx + length * np.cos(angles[i]), gy + length * np.sin(angles[i]),
                     h, w, rows, cols)
        for j in range(n):
            row = rows[j]
            col = cols[j]
            if stamp[row, col] != scan_id:
                logodds[row, col] = max(logodds[row, col] + miss, lo)
                stamp[row, col] = scan_id
