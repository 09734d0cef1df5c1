"""The pose check's kernels as they were before the pose check's own kernels: a frozen copy
of ``sensor_in_map``, ``likelihood_field``, ``beam_cells`` and ``interpolated_fit`` from
``localization/_kernels.py``."""

import math

import numpy as np
from numba import njit

@njit(cache=True)
def sensor_in_map(pose, mount):
    """(x, y, cos, sin) of the sensor's pose in the map frame for a robot ``pose`` and the
    sensor's ``mount`` in the robot frame."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    cm, sm = math.cos(mount[2]), math.sin(mount[2])
    return (pose[0] + c * mount[0] - s * mount[1], pose[1] + s * mount[0] + c * mount[1],
            c * cm - s * sm, s * cm + c * sm)


# Particles scored per block: the block's sensor poses, indices and sums stay in the L1 cache.
SCORE_BLOCK = 256


@njit(cache=True)
def likelihood_field(poses, mount, beams, table, frame, off_value, base, out):
    """Likelihood-field score of every particle: ``out[i] = base + sum_j table[cell of beam j's
    end point]`` (AMCL: base 1 and pz^3 per cell; or base 0 and log pz). ``beams`` (B, 2) are
    the end points in the sensor frame [m], ``mount`` the sensor in the robot frame, ``frame`` =
    (origin x, origin y, resolution); end points off the grid score ``off_value``. Rotating the
    precomputed beam vectors avoids any trigonometry per beam.

    Beams are the outer loop and a block of particles the inner one: the cell arithmetic then
    runs over independent particles, which the compiler turns into vector code, while each
    particle's sum still adds its beams in beam order, so the scores are those of a beam-by-beam
    loop to the bit."""
    n = poses.shape[0]
    pose_block = np.empty((4, SCORE_BLOCK))
    cells = np.empty(SCORE_BLOCK, np.int64)
    acc = np.empty(SCORE_BLOCK)
    flat = table.ravel()
    for start in range(0, n, SCORE_BLOCK):
        m = min(SCORE_BLOCK, n - start)
        for k in range(m):
            sx, sy, cs, ss = sensor_in_map(poses[start + k], mount)
            pose_block[0, k], pose_block[1, k], pose_block[2, k], pose_block[3, k] = sx, sy, cs, ss
            acc[k] = base
        for j in range(beams.shape[0]):
            beam_cells(pose_block, m, beams[j, 0], beams[j, 1], frame, table.shape, cells)
            for k in range(m):
                c = cells[k]
                if c >= 0:
                    acc[k] += flat[c]
                else:
                    acc[k] += off_value
        out[start:start + m] = acc[:m]


@njit(cache=True)
def beam_cells(pose_block, m, bx, by, frame, shape, cells):
    """The flat cell index of the end point (bx, by) seen from each of the first ``m`` sensor
    poses of ``pose_block`` (rows x, y, cos, sin), -1 off the grid. Kept free of loads from the
    table so that it vectorises; the arithmetic is the one ``likelihood_field`` always used."""
    h, w = shape
    ox, oy, inv_res = frame[0], frame[1], 1.0 / frame[2]
    fw, fh = float(w), float(h)
    for k in range(m):
        sx, sy, cs, ss = pose_block[0, k], pose_block[1, k], pose_block[2, k], pose_block[3, k]
        gx = (sx + cs * bx - ss * by - ox) * inv_res
        gy = (sy + ss * bx + cs * by - oy) * inv_res
        inside = (gx >= 0.0) & (gy >= 0.0) & (gx < fw) & (gy < fh)
        cells[k] = np.int64(gy) * w + np.int64(gx) if inside else -1


@njit(cache=True)
def interpolated_fit(poses, mount, beams, residual, frame, out):
    """Mean squared residual of every pose: ``out[i] = mean_j r(end point j)^2`` with r the
    ``residual`` grid (values at cell centres) interpolated bilinearly, so the score is smooth
    below a cell, unlike a per-cell table. Arguments as in ``likelihood_field``; end points
    off the grid score 1."""
    h, w = residual.shape
    ox, oy, inv_res = frame[0], frame[1], 1.0 / frame[2]
    for i in range(poses.shape[0]):
        sx, sy, cs, ss = sensor_in_map(poses[i], mount)
        total = 0.0
        for j in range(beams.shape[0]):
            gx = (sx + cs * beams[j, 0] - ss * beams[j, 1] - ox) * inv_res - 0.5
            gy = (sy + ss * beams[j, 0] + cs * beams[j, 1] - oy) * inv_res - 0.5
            if gx < 0.0 or gy < 0.0 or gx > w - 1 or gy > h - 1:
                total += 1.0
                continue
            c0, r0 = min(int(gx), w - 2), min(int(gy), h - 2)
            fx, fy = gx - c0, gy - r0
            v = (residual[r0, c0] * (1 - fx) + residual[r0, c0 + 1] * fx) * (1 - fy) + \
                (residual[r0 + 1, c0] * (1 - fx) + residual[r0 + 1, c0 + 1] * fx) * fy
            total += v * v
        out[i] = total / max(beams.shape[0], 1)

