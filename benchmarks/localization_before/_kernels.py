"""numba kernels of the localiser: motion sampling, likelihood-field scoring, KLD bin counting
and particle clustering. Arrays and scalars only; each is called once per update with all
particles. Poses are rows (x [m], y [m], theta [rad]).
"""

import math

import numpy as np
from numba import njit

from gridmap._kernels import find_root

# Bin keys pack (ix, iy, itheta) into one int64: ix, iy offset by KEY_OFFSET into [0, KEY_SPAN).
KEY_OFFSET = 1 << 20
KEY_SPAN = 1 << 21


@njit(cache=True)
def wrap(a):
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True)
def sample_motion_odometry(poses, delta, sigmas, noise):
    """Move every particle by the odometry step ``delta`` = (rot1, trans, rot2) [rad, m, rad]
    perturbed by ``sigmas`` * ``noise`` (N, 3 standard normals), in place (Probabilistic
    Robotics table 5.6, as nav2's DifferentialMotionModel)."""
    for i in range(poses.shape[0]):
        rot1 = delta[0] - sigmas[0] * noise[i, 0]
        trans = delta[1] - sigmas[1] * noise[i, 1]
        rot2 = delta[2] - sigmas[2] * noise[i, 2]
        th = poses[i, 2]
        poses[i, 0] += trans * math.cos(th + rot1)
        poses[i, 1] += trans * math.sin(th + rot1)
        poses[i, 2] = wrap(th + rot1 + rot2)


@njit(cache=True)
def sensor_in_map(pose, mount):
    """(x, y, cos, sin) of the sensor's pose in the map frame for a robot ``pose`` and the
    sensor's ``mount`` in the robot frame."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    cm, sm = math.cos(mount[2]), math.sin(mount[2])
    return (pose[0] + c * mount[0] - s * mount[1], pose[1] + s * mount[0] + c * mount[1],
            c * cm - s * sm, s * cm + c * sm)


@njit(cache=True)
def likelihood_field(poses, mount, beams, table, frame, off_value, base, out):
    """Likelihood-field score of every particle: ``out[i] = base + sum_j table[cell of beam j's
    end point]`` (AMCL: base 1 and pz^3 per cell; or base 0 and log pz). ``beams`` (B, 2) are
    the end points in the sensor frame [m], ``mount`` the sensor in the robot frame, ``frame`` =
    (origin x, origin y, resolution); end points off the grid score ``off_value``. Rotating the
    precomputed beam vectors avoids any trigonometry per beam."""
    h, w = table.shape
    ox, oy, inv_res = frame[0], frame[1], 1.0 / frame[2]
    for i in range(poses.shape[0]):
        sx, sy, cs, ss = sensor_in_map(poses[i], mount)
        p = base
        for j in range(beams.shape[0]):
            gx = (sx + cs * beams[j, 0] - ss * beams[j, 1] - ox) * inv_res
            gy = (sy + ss * beams[j, 0] + cs * beams[j, 1] - oy) * inv_res
            if gx >= 0.0 and gy >= 0.0 and gx < w and gy < h:
                p += table[int(gy), int(gx)]
            else:
                p += off_value
        out[i] = p


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


@njit(cache=True)
def bin_keys(poses, bin_size, n_theta, out):
    """The KLD histogram bin of every pose as one int64 key; theta bins wrap around."""
    for i in range(poses.shape[0]):
        ix = min(max(math.floor(poses[i, 0] / bin_size[0]), -KEY_OFFSET), KEY_OFFSET - 1)
        iy = min(max(math.floor(poses[i, 1] / bin_size[1]), -KEY_OFFSET), KEY_OFFSET - 1)
        it = min(int((wrap(poses[i, 2]) + math.pi) / bin_size[2]), n_theta - 1)
        out[i] = ((ix + KEY_OFFSET) * KEY_SPAN + (iy + KEY_OFFSET)) * n_theta + it


@njit(cache=True)
def resample_limit(k, pf_err, pf_z, min_n, max_n):
    """Fox's KLD bound on the sample count for ``k`` occupied bins, clamped as AMCL does."""
    if k <= 1:
        return max_n
    b = 2.0 / (9.0 * (k - 1))
    x = 1.0 - b + math.sqrt(b) * pf_z
    n = int(math.ceil((k - 1) / (2.0 * pf_err) * x * x * x))
    return min(max(n, min_n), max_n)


@njit(cache=True)
def kld_sample_count(keys, pf_err, pf_z, min_n, max_n, table):
    """How many of the candidate samples (bin ``keys`` in draw order) KLD-sampling keeps: take
    them one by one, counting occupied bins in the open-addressing set ``table`` (power-of-two
    length, filled with -1), and stop once the count exceeds the bound, as AMCL does."""
    mask = table.shape[0] - 1
    k = 0
    n = min(keys.shape[0], max_n)
    for m in range(n):
        key = keys[m]
        h = ((key * 2654435761) ^ (key >> 16)) & mask
        while table[h] != -1 and table[h] != key:
            h = (h + 1) & mask
        if table[h] == -1:
            table[h] = key
            k += 1
        if m + 1 > resample_limit(k, pf_err, pf_z, min_n, max_n):
            return m + 1
    return n


@njit(cache=True)
def cluster_bins(keys, n_theta, labels):
    """Label particles by connected groups of occupied bins (26-neighbours, theta wrapping), as
    AMCL's kd-tree clustering; writes ``labels`` (N,) and returns the number of clusters."""
    ukeys = np.unique(keys)
    nb = ukeys.shape[0]
    parent = np.arange(nb)
    for b in range(nb):
        it = ukeys[b] % n_theta
        cell = ukeys[b] // n_theta
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                for dt in range(-1, 2):
                    nkey = (cell + dx * KEY_SPAN + dy) * n_theta + (it + dt) % n_theta
                    j = np.searchsorted(ukeys, nkey)
                    if j < nb and ukeys[j] == nkey:
                        ra, rb = find_root(parent, b), find_root(parent, j)
                        if ra != rb:
                            parent[max(ra, rb)] = min(ra, rb)
    bin_label = np.full(nb, -1)
    count = 0
    for b in range(nb):
        r = find_root(parent, b)
        if bin_label[r] < 0:
            bin_label[r] = count
            count += 1
        bin_label[b] = bin_label[r]
    for i in range(keys.shape[0]):
        labels[i] = bin_label[np.searchsorted(ukeys, keys[i])]
    return count
