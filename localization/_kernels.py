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
    """``(a + pi) % (2 pi) - pi``, as NumPy and Python wrap an angle to [-pi, pi)."""
    t = a + math.pi
    # fmod(t, 2 pi) is t itself for 0 < t < 2 pi, where nearly every angle lies, and a call
    # to fmod costs more than the rest of a bin key
    if 0.0 < t < 2.0 * math.pi:
        return t - math.pi
    return t % (2.0 * math.pi) - math.pi


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



# The pose check scores regular grids of poses around one pose: (x offsets) x (y offsets) x
# (heading offsets). An end point's map column depends only on a pose's x and heading, its row
# only on its y and heading, so for each heading and beam the columns of every x offset and the
# rows of every y offset are found once and combined, instead of transforming the end point
# anew for each of the grid's poses. The arithmetic per coordinate is ``sensor_in_map``'s and
# ``beam_cells``' (or ``interpolated_fit``'s), and each pose adds its beams in beam order, so
# the scores are theirs to the bit for the poses ``base + (x, y, heading offset)``. The loops
# over the grid stay in the kernel's own body: with the innermost one in a helper called per
# row of sums, the calls (arrays passed, a row as a view) cost several times the sums.


@njit(cache=True)
def sensor_axes(base, mount, xs, ys, turn, sx, sy):
    """The sensor at heading ``base[2] + turn``: its x for the robot at ``base[0] + xs[a]``
    into ``sx[a]``, its y for the robot at ``base[1] + ys[b]`` into ``sy[b]``, and (cos, sin)
    of its heading in the map; ``sensor_in_map`` split by axis."""
    th = base[2] + turn
    c, s = math.cos(th), math.sin(th)
    cm, sm = math.cos(mount[2]), math.sin(mount[2])
    for a in range(xs.shape[0]):
        sx[a] = (base[0] + xs[a]) + c * mount[0] - s * mount[1]
    for b in range(ys.shape[0]):
        sy[b] = (base[1] + ys[b]) + s * mount[0] + c * mount[1]
    return c * cm - s * sm, s * cm + c * sm


# Beams added between two looks at which poses of a grid can still reach the floor.
PRUNE_EVERY = 8
# How far below the floor a sum must lie to be dropped: then it stays below the floor's sum
# after both are divided by the beam count and rounded, so the two cannot tie.
FLOOR_SLACK = 1e-9


@njit(cache=True)
def grid_table_sums(base, mount, beams, table, frame, off_value, xs, ys, turns, floor, out):
    """``likelihood_field`` with base 0 on the grid of poses ``base + (xs[a], ys[b],
    turns[t])``: ``out[(a * len(ys) + b) * len(turns) + t]`` is the sum over the beams of
    ``table`` at the beam's end point, ``off_value`` off the grid.

    With ``table`` and ``off_value`` <= 0 a sum can only fall as beams are added, so a pose
    whose sum so far lies more than FLOOR_SLACK below ``floor`` cannot end above it: the poses
    of one x offset and heading are dropped once all of theirs do, and get -inf. A caller
    after the greatest sum passes the sum of one of the grid's poses (or -inf to drop none)."""
    h, w = table.shape
    nx, ny, nt = xs.shape[0], ys.shape[0], turns.shape[0]
    ox, oy, inv_res = frame[0], frame[1], 1.0 / frame[2]
    fw, fh = float(w), float(h)
    flat = table.ravel()
    sx, sy = np.empty(nx), np.empty(ny)
    cols, rows = np.empty(nx, np.int64), np.empty(ny, np.int64)    # -1: off the grid
    acc, live = np.empty(nx * ny), np.empty(nx, np.bool_)
    for t in range(nt):
        cs, ss = sensor_axes(base, mount, xs, ys, turns[t], sx, sy)
        acc[:] = 0.0
        live[:] = True
        for j in range(beams.shape[0]):
            bx, by = beams[j, 0], beams[j, 1]
            for a in range(nx):
                gx = (sx[a] + cs * bx - ss * by - ox) * inv_res
                cols[a] = np.int64(gx) if (gx >= 0.0) & (gx < fw) else -1
            for b in range(ny):
                gy = (sy[b] + ss * bx + cs * by - oy) * inv_res
                rows[b] = np.int64(gy) * w if (gy >= 0.0) & (gy < fh) else -1
            for a in range(nx):
                col, k = cols[a], a * ny
                if not live[a]:
                    continue
                if col < 0:
                    for b in range(ny):
                        acc[k + b] += off_value
                    continue
                for b in range(ny):
                    r = rows[b]
                    acc[k + b] += flat[r + col] if r >= 0 else off_value
            if (j + 1) % PRUNE_EVERY == 0 and floor > -np.inf and \
                    not keep_live(acc, ny, floor - FLOOR_SLACK, live):
                break
        for k in range(nx * ny):
            out[k * nt + t] = acc[k] if live[k // ny] else -np.inf


@njit(cache=True)
def keep_live(acc, ny, least, live):
    """Keep ``live[a]`` only where a sum ``acc[a * ny + b]`` is at least ``least``; whether any
    is."""
    any_live = False
    for a in range(live.shape[0]):
        if live[a]:
            keep = False
            for b in range(ny):
                keep |= acc[a * ny + b] >= least
            live[a] = keep
            any_live |= keep
    return any_live


@njit(cache=True)
def grid_interpolated_fit(base, mount, beams, residual, frame, xs, ys, turns, out):
    """``interpolated_fit`` on the grid of poses ``base + (xs[a], ys[b], turns[t])`` into
    ``out[(a * len(ys) + b) * len(turns) + t]``, for a ``residual`` grid of at least 2 x 2
    cells."""
    h, w = residual.shape
    nx, ny, nt = xs.shape[0], ys.shape[0], turns.shape[0]
    ox, oy, inv_res = frame[0], frame[1], 1.0 / frame[2]
    flat = residual.ravel()
    sx, sy = np.empty(nx), np.empty(ny)
    cols, rows = np.empty(nx, np.int64), np.empty(ny, np.int64)    # -1: off the grid
    fx, fy, gy = np.empty(nx), np.empty(ny), np.empty(ny)
    total = np.empty(nx * ny)
    for t in range(nt):
        cs, ss = sensor_axes(base, mount, xs, ys, turns[t], sx, sy)
        total[:] = 0.0
        for j in range(beams.shape[0]):
            bx, by = beams[j, 0], beams[j, 1]
            for a in range(nx):
                cols[a], fx[a] = cell_fraction((sx[a] + cs * bx - ss * by - ox) * inv_res - 0.5,
                                               w)
            for b in range(ny):
                r, fy[b] = cell_fraction((sy[b] + ss * bx + cs * by - oy) * inv_res - 0.5, h)
                rows[b] = r * w if r >= 0 else -1
                gy[b] = 1 - fy[b]
            for a in range(nx):
                col, k = cols[a], a * ny
                if col < 0:
                    for b in range(ny):
                        total[k + b] += 1.0
                    continue
                f, g = fx[a], 1 - fx[a]
                for b in range(ny):
                    if rows[b] < 0:
                        total[k + b] += 1.0
                    else:
                        i = rows[b] + col
                        v = (flat[i] * g + flat[i + 1] * f) * gy[b] + \
                            (flat[i + w] * g + flat[i + w + 1] * f) * fy[b]
                        total[k + b] += v * v
        for k in range(nx * ny):
            out[k * nt + t] = total[k] / max(beams.shape[0], 1)


@njit(cache=True)
def cell_fraction(g, n):
    """(first cell, fraction) of grid coordinate ``g`` between the centres of an axis of ``n``
    >= 2 cells, as ``interpolated_fit`` takes them; (-1, 0) off the grid."""
    if g < 0.0 or g > n - 1:
        return -1, 0.0
    k = min(int(g), n - 2)
    return k, g - k


@njit(cache=True)
def bin_key(pose, bin_size, n_theta):
    """The KLD histogram bin of one pose as one int64 key; theta bins wrap around."""
    ix = min(max(math.floor(pose[0] / bin_size[0]), -KEY_OFFSET), KEY_OFFSET - 1)
    iy = min(max(math.floor(pose[1] / bin_size[1]), -KEY_OFFSET), KEY_OFFSET - 1)
    it = min(int((wrap(pose[2]) + math.pi) / bin_size[2]), n_theta - 1)
    return ((ix + KEY_OFFSET) * KEY_SPAN + (iy + KEY_OFFSET)) * n_theta + it


@njit(cache=True)
def bin_keys(poses, bin_size, n_theta, out):
    """The KLD histogram bin of every pose as one int64 key."""
    for i in range(poses.shape[0]):
        out[i] = bin_key(poses[i], bin_size, n_theta)


@njit(cache=True)
def hash_slot(table, key):
    """The slot of ``key`` in the open-addressing set ``table`` (power-of-two length, -1 for
    empty), or the empty slot where it would go."""
    mask = table.shape[0] - 1
    h = ((key * 2654435761) ^ (key >> 16)) & mask
    while table[h] != -1 and table[h] != key:
        h = (h + 1) & mask
    return h


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


@njit(cache=True)
def kld_take(poses, order, bin_size, n_theta, pf_err, pf_z, min_n, max_n, table, out):
    """KLD-sampling in one pass: copy ``poses[order[m]]`` to ``out[m]`` for m = 0, 1, ... and
    stop where ``kld_sample_count`` on their bin keys would; returns that count. Only the kept
    samples are copied. ``table`` is an open-addressing set of length >= 2 len(order) (power of
    two, all -1) and is left all -1 again."""
    k = 0
    n = min(order.shape[0], max_n)
    used = np.empty(n, np.int64)
    taken = n
    limit = max_n               # resample_limit's bound for no bin yet; it changes only with k
    for m in range(n):
        src = order[m]
        for d in range(3):
            out[m, d] = poses[src, d]
        key = bin_key(out[m], bin_size, n_theta)
        h = hash_slot(table, key)
        if table[h] == -1:
            table[h] = key
            used[k] = h
            k += 1
            limit = resample_limit(k, pf_err, pf_z, min_n, max_n)
        if m + 1 > limit:
            taken = m + 1
            break
    table[used[:k]] = -1
    return taken


@njit(cache=True)
def systematic_take(cum, u, count, out):
    """Systematic resampling's indices into ``out`` (count,): the first index whose cumulative
    weight ``cum`` exceeds (u + k) / count, found by one merge walk since both rise. Returns
    False, writing nothing, where ``cum`` does not rise (a rounded sum above 1 before its last
    entry, which is set to exactly 1), so the caller keeps a binary search's answer."""
    nc = cum.shape[0]
    for i in range(nc - 1):
        if cum[i + 1] < cum[i]:
            return False
    j = 0
    for k in range(count):
        p = (u + k) / count
        while j < nc and cum[j] <= p:
            j += 1
        out[k] = j
    return True


@njit(cache=True)
def join_bins(bkeys, n_theta, table, ids):
    """Union-find over the occupied bins ``bkeys`` (each in the set ``table``, its index in
    ``ids`` at the same slot): bins that touch (26-neighbours, theta wrapping) share a root, and
    each root is the bin of least key in its group."""
    nb = bkeys.shape[0]
    # int32, as the map updater's union-finds: find_root is then compiled once for both
    parent = np.arange(nb).astype(np.int32)
    for b in range(nb):
        it = bkeys[b] % n_theta
        cell = bkeys[b] // n_theta
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                for dt in range(-1, 2):
                    nkey = (cell + dx * KEY_SPAN + dy) * n_theta + (it + dt) % n_theta
                    if nkey < 0:        # -1 marks an empty slot; no bin has a negative key
                        continue
                    h = hash_slot(table, nkey)
                    if table[h] != nkey:
                        continue
                    ra, rb = find_root(parent, b), find_root(parent, ids[h])
                    if ra != rb:
                        if bkeys[ra] < bkeys[rb]:
                            parent[rb] = ra
                        else:
                            parent[ra] = rb
    return parent


@njit(cache=True)
def cluster_particles(poses, weights, bin_size, n_theta, table, labels):
    """AMCL's clusters in one pass over the particles, as ``cluster_bins`` of their
    ``bin_keys`` labels them (clusters numbered in the order of their least bin key), without
    sorting: bins are found in the set ``table`` (see ``kld_take``; left all -1 again). Writes
    ``labels`` (N,) and returns each cluster's summed weight and particle count, the sums taken
    in particle order as ``np.bincount`` takes them."""
    n = poses.shape[0]
    ids = np.empty(table.shape[0], np.int64)
    bkeys = np.empty(n, np.int64)
    slots = np.empty(n, np.int64)
    nb = 0
    for i in range(n):
        key = bin_key(poses[i], bin_size, n_theta)
        h = hash_slot(table, key)
        if table[h] == -1:
            table[h], ids[h], bkeys[nb], slots[nb] = key, nb, key, h
            nb += 1
        labels[i] = ids[h]
    parent = join_bins(bkeys[:nb], n_theta, table, ids)
    table[slots[:nb]] = -1
    root = np.empty(nb, np.int64)
    for b in range(nb):
        root[b] = find_root(parent, b)
    roots = np.flatnonzero(root == np.arange(nb))
    root_label = np.empty(nb, np.int64)
    root_label[roots[np.argsort(bkeys[roots])]] = np.arange(roots.shape[0])
    share = np.zeros(roots.shape[0])
    counts = np.zeros(roots.shape[0], np.int64)
    for i in range(n):
        lab = root_label[root[labels[i]]]
        labels[i] = lab
        share[lab] += weights[i]
        counts[lab] += 1
    return share, counts


@njit(cache=True)
def take_label(poses, weights, labels, label, out_poses, out_weights):
    """The particles of cluster ``label``, in order, into ``out_poses`` and ``out_weights``."""
    c = 0
    for i in range(poses.shape[0]):
        if labels[i] == label:
            for d in range(3):
                out_poses[c, d] = poses[i, d]
            out_weights[c] = weights[i]
            c += 1


@njit(cache=True)
def centred(poses, mean, weights, d, dw):
    """``d = poses - mean`` with the heading wrapped, and ``dw = d * weights[:, None]``: the
    same per-element arithmetic as the NumPy expressions, in one pass."""
    for i in range(poses.shape[0]):
        d[i, 0] = poses[i, 0] - mean[0]
        d[i, 1] = poses[i, 1] - mean[1]
        d[i, 2] = wrap(poses[i, 2] - mean[2])
        for k in range(3):
            dw[i, k] = d[i, k] * weights[i]
