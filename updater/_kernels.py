"""numba kernels of the map updater. Arrays and scalars only; each is called once per scan.

Units: points are in grid units, (gx, gy) = ((x - ox) / res, (y - oy) / res), so a point lies in
cell (row, col) = (floor(gy), floor(gx)); ranges and distances that come from the configuration
are in metres and are divided by ``res`` here. Cells are addressed by their flat index
``row * width + col``. Per-scan marks and the decided state are bit planes: one bit per cell,
packed eight to a byte (``bits[idx >> 3] >> (idx & 7)``).
"""

import numpy as np
from numba import njit

from gridmap._kernels import NO_HIT, find_root, first_hit, traverse

FREE = 0
OCC = 100
# Per-beam verdicts of the classifier.
INVALID = 0
UNCHANGED = 1
SKIPPED = 2
CHANGE = 3


# --- bits and counts --------------------------------------------------------------------------
@njit(cache=True)
def bit_get(bits, idx):
    return (bits[idx >> 3] >> (idx & 7)) & 1


@njit(cache=True)
def test_and_set(bits, idx):
    """Set the bit of cell ``idx``; False if it was already set."""
    b = idx >> 3
    m = 1 << (idx & 7)
    if bits[b] & m:
        return False
    bits[b] = bits[b] | m
    return True


@njit(cache=True)
def popcount16(v):
    x = np.int64(v)
    x = x - ((x >> 1) & 0x5555)
    x = (x & 0x3333) + ((x >> 2) & 0x3333)
    x = (x + (x >> 4)) & 0x0F0F
    return (x + (x >> 8)) & 0x1F


# --- 1. beam classifier -----------------------------------------------------------------------
@njit(cache=True)
def beam_endpoints(ranges, sensor, geom, res, out_r, out_hx, out_hy, out_valid):
    """Valid beams and their hit points. ``sensor`` = (gx, gy, yaw [rad]); ``geom`` =
    (angle_min [rad], angle_increment [rad], r_lo [m], r_hi [m]). A beam is valid when its range
    r is finite, r > 0, r >= r_lo and r < r_hi. Returns (valid beams, the summed lengths of
    their walks in cells, the cell count of the box around the sensor and the hits)."""
    gx0, gy0 = sensor[0], sensor[1]
    c_lo, c_hi = int(np.floor(gx0)), int(np.floor(gx0))
    r_lo, r_hi = int(np.floor(gy0)), int(np.floor(gy0))
    n_valid = 0
    walk = 0
    for i in range(ranges.shape[0]):
        r = np.float64(ranges[i])
        ok = np.isfinite(r) and r > 0.0 and r >= geom[2] and r < geom[3]
        out_valid[i] = ok
        if not ok:
            continue
        a = sensor[2] + geom[0] + i * geom[1]
        hx = gx0 + r / res * np.cos(a)
        hy = gy0 + r / res * np.sin(a)
        out_r[i] = r
        out_hx[i] = hx
        out_hy[i] = hy
        n_valid += 1
        c, rw = int(np.floor(hx)), int(np.floor(hy))
        walk += abs(c - int(np.floor(gx0))) + abs(rw - int(np.floor(gy0))) + 7
        c_lo, c_hi = min(c_lo, c), max(c_hi, c)
        r_lo, r_hi = min(r_lo, rw), max(r_hi, rw)
    return n_valid, walk, (c_hi - c_lo + 3) * (r_hi - r_lo + 3)


@njit(cache=True)
def cast_virtual(ref, sensor, angle_min, step, max_len, out_ex, out_ey, out_ok):
    """Cast the virtual beams once: beam j at ``angle_min + j * step`` (sensor frame) ends at the
    first occupied-or-unknown cell of ``ref``, or where it leaves the map (outside is unknown);
    ``out_ok[j]`` is False when nothing blocks it within ``max_len`` grid units."""
    gx0, gy0 = sensor[0], sensor[1]
    for j in range(out_ex.shape[0]):
        a = sensor[2] + angle_min + j * step
        ca, sa = np.cos(a), np.sin(a)
        t, status = first_hit(ref, gx0, gy0, ca, sa, max_len, True)
        out_ok[j] = status != NO_HIT
        out_ex[j] = gx0 + t * ca
        out_ey[j] = gy0 + t * sa


@njit(cache=True)
def classify(hx, hy, r, valid, ex, ey, eok, ratio, half_window, wrap, dpar, res, out_change):
    """A valid beam i is a detected change when no expected point in the window of virtual
    beams ``i * ratio +- half_window`` lies closer than D(r_i) to its hit point. The window is
    searched nearest index first and wraps around the ends only when ``wrap``. ``dpar`` =
    (D near [m], range near [m], slope [m/m], D max [m]). Returns the count of changes."""
    m = ex.shape[0]
    n_change = 0
    for i in range(hx.shape[0]):
        out_change[i] = False
        if not valid[i]:
            continue
        d = min(dpar[0] + dpar[2] * (r[i] - dpar[1]), dpar[3]) / res
        d2 = d * d
        found = False
        for k in range(2 * half_window + 1):
            j = i * ratio + ((k + 1) // 2 if k % 2 == 1 else -(k // 2))
            if wrap:
                j = j % m
            elif j < 0 or j >= m:
                continue
            if eok[j] and (hx[i] - ex[j]) ** 2 + (hy[i] - ey[j]) ** 2 < d2:
                found = True
                break
        if not found:
            out_change[i] = True
            n_change += 1
    return n_change


@njit(cache=True)
def run_filter(change, min_run, wrap, out_keep):
    """Keep a change only inside a run of at least ``min_run`` consecutive changes (a beam that
    is not a change, invalid ones included, ends a run). With ``wrap`` a run may cross the
    scan's ends. Returns the count kept."""
    n = change.shape[0]
    out_keep[:] = False
    start = 0
    if wrap:
        start = -1
        for i in range(n):
            if not change[i]:
                start = i + 1   # begin after a non-change, so no run is cut at the ends
                break
        if start < 0:           # every beam is a change: one run around the circle
            if n >= min_run:
                out_keep[:] = True
                return n
            return 0
    kept = 0
    run = 0
    for k in range(n + 1):
        if k < n and change[(start + k) % n]:
            run += 1
            continue
        if run >= min_run:
            for q in range(k - run, k):
                out_keep[(start + q) % n] = True
            kept += run
        run = 0
    return kept


@njit(cache=True)
def beam_verdicts(valid, keep, n_skip, wrap, out_verdict):
    """CHANGE for kept changes, INVALID for invalid beams, SKIPPED for other beams within
    ``n_skip`` beams of a change, UNCHANGED for the rest. An invalid beam blocks nothing."""
    n = valid.shape[0]
    for i in range(n):
        out_verdict[i] = CHANGE if keep[i] else (UNCHANGED if valid[i] else INVALID)
    for i in range(n):
        if not keep[i]:
            continue
        for k in range(1, n_skip + 1):
            for j in (i - k, i + k):
                if wrap:
                    j = j % n
                elif j < 0 or j >= n:
                    continue
                if out_verdict[j] == UNCHANGED:
                    out_verdict[j] = SKIPPED


# --- 2. changed-cells evaluator ---------------------------------------------------------------
@njit(cache=True)
def disc_is_free(ref, px, py, rad):
    """True when every cell of ``ref`` that meets the open disc of radius ``rad`` (grid units)
    around (px, py) is free; cells off the map are unknown, so not free."""
    height, width = ref.shape
    for row in range(int(np.floor(py - rad)), int(np.floor(py + rad)) + 1):
        qy = min(max(py, row), row + 1.0) - py
        for col in range(int(np.floor(px - rad)), int(np.floor(px + rad)) + 1):
            qx = min(max(px, col), col + 1.0) - px
            if qx * qx + qy * qy >= rad * rad:
                continue
            if row < 0 or row >= height or col < 0 or col >= width or ref[row, col] != FREE:
                return False
    return True


@njit(cache=True)
def walk_cells(ref, gx0, gy0, frac, hx, hy, not_free, skip_last, marks, rows, cols, out, n):
    """Append to ``out`` (from position n) the cells on the segment from the sensor to the
    point at ``frac`` of the way to the hit that are occupied-or-unknown (``not_free``) or free
    in ``ref`` and not yet marked; ``skip_last`` leaves out the cell holding that point.
    Returns the new count."""
    height, width = ref.shape
    flat = ref.reshape(-1)
    tx = gx0 + frac * (hx - gx0)
    ty = gy0 + frac * (hy - gy0)
    steps = traverse(gx0, gy0, tx, ty, height, width, rows, cols)
    if skip_last and 0.0 <= tx < width and 0.0 <= ty < height:
        steps -= 1
    for k in range(steps):
        idx = rows[k] * width + cols[k]
        if (flat[idx] != FREE) == not_free and test_and_set(marks, idx):
            out[n] = idx
            n += 1
    return n


@njit(cache=True)
def flag_changed(ref, hx, hy, r, verdict, sensor, tpar, res, marks, rows, cols, out):
    """Changed flags of the detected-change beams, each cell at most once (``marks``).
    New obstacle: the hit cell, if every cell within tol(r) of the hit is free in ``ref``.
    Removed obstacle: the occupied-or-unknown cells from the sensor to p_th, short of the hit by
    max(fraction * r, minimum), all but the last. ``tpar`` = (tol near [m], tol far [m],
    far range [m], skip fraction, skip minimum [m]). Returns (cells flagged, new-obstacle
    flags)."""
    width = ref.shape[1]
    n = 0
    n_new = 0
    for i in range(hx.shape[0]):
        if verdict[i] != CHANGE:
            continue
        tol = tpar[0] + (tpar[1] - tpar[0]) * min(r[i] / tpar[2], 1.0)
        if disc_is_free(ref, hx[i], hy[i], tol / res):
            idx = int(np.floor(hy[i])) * width + int(np.floor(hx[i]))
            if test_and_set(marks, idx):
                out[n] = idx
                n += 1
                n_new += 1
        skip = max(tpar[3] * r[i], tpar[4])
        if skip < r[i]:
            n = walk_cells(ref, sensor[0], sensor[1], 1.0 - skip / r[i], hx[i], hy[i], True,
                           True, marks, rows, cols, out, n)
    return n, n_new


@njit(cache=True)
def protect_seen(ref, enclosed, hx, hy, verdict, radius, marks, out):
    """Mark (in ``marks``, so the removed-obstacle walk passes them by) the cells of ``ref``
    that come within ``radius`` (grid units) of the hit point of any valid beam and are
    occupied, or unknown outside the ``enclosed`` regions, and list them in ``out``. Enclosed
    unknown cells (an object's interior) are left to the walk: a hit near one is on the face
    of whatever still stands beside it, and the last check closes what stays unknown next to a
    freed cell. Returns the count listed."""
    height, width = ref.shape
    n = 0
    r2 = radius * radius
    for i in range(hx.shape[0]):
        if verdict[i] == INVALID:
            continue
        x, y = hx[i], hy[i]
        for row in range(max(int(np.floor(y - radius)), 0),
                         min(int(np.floor(y + radius)) + 1, height)):
            dy = max(row - y, 0.0, y - row - 1.0)
            for col in range(max(int(np.floor(x - radius)), 0),
                             min(int(np.floor(x + radius)) + 1, width)):
                dx = max(col - x, 0.0, x - col - 1.0)
                if dx * dx + dy * dy > r2:
                    continue
                v = ref[row, col]
                idx = row * width + col
                if v == FREE or (v != OCC and bit_get(enclosed, idx)):
                    continue
                if test_and_set(marks, idx):
                    out[n] = idx
                    n += 1
    return n


@njit(cache=True)
def clear_marks(marks, cells, n):
    for k in range(n):
        marks[cells[k] >> 3] = 0


@njit(cache=True)
def flag_gaps(ref, hx, hy, verdict, clearance, marks, out, n):
    """Changed flags, appended to ``out`` from position n, for the hit cells of UNCHANGED beams
    whose square of ``clearance`` cells each way is free in ``ref`` (a surface where M has
    nothing that near). Returns (new count, cells flagged here)."""
    height, width = ref.shape
    n0 = n
    k = clearance
    for i in range(hx.shape[0]):
        if verdict[i] != UNCHANGED:
            continue
        row0 = int(np.floor(hy[i]))
        col0 = int(np.floor(hx[i]))
        if row0 < k or row0 >= height - k or col0 < k or col0 >= width - k:
            continue
        free = True
        for dr in range(-k, k + 1):
            for dc in range(-k, k + 1):
                if ref[row0 + dr, col0 + dc] != FREE:
                    free = False
                    break
            if not free:
                break
        if free and test_and_set(marks, row0 * width + col0):
            out[n] = row0 * width + col0
            n += 1
    return n, n - n0


# --- 3. unchanged-cells evaluator -------------------------------------------------------------
@njit(cache=True)
def flag_unchanged(ref, hx, hy, r, verdict, sensor, free_fraction, free_margin, marks, rows,
                   cols, out):
    """Unchanged flags of the UNCHANGED beams, each cell at most once (``marks``).
    Occupied: every occupied-or-unknown cell among the hit cell and its 4-neighbours.
    Free: every free cell on the beam up to ``free_fraction`` of its range ``r`` or, when
    ``free_margin`` > 0, up to ``free_margin`` (same unit as ``r``) short of the hit if that
    reaches further. Returns the count."""
    height, width = ref.shape
    n = 0
    for i in range(hx.shape[0]):
        if verdict[i] != UNCHANGED:
            continue
        row0 = int(np.floor(hy[i]))
        col0 = int(np.floor(hx[i]))
        for dr, dc in ((0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)):
            row, col = row0 + dr, col0 + dc
            if 0 <= row < height and 0 <= col < width and ref[row, col] != FREE:
                if test_and_set(marks, row * width + col):
                    out[n] = row * width + col
                    n += 1
        frac = free_fraction
        if 0 < free_margin < r[i]:
            frac = max(frac, 1.0 - free_margin / r[i])
        n = walk_cells(ref, sensor[0], sensor[1], frac, hx[i], hy[i], False, False, marks,
                       rows, cols, out, n)
    return n


# --- buffers and decision ---------------------------------------------------------------------
@njit(cache=True)
def push_flags(hist, changed, n_changed, unchanged, n_unchanged, mask, threshold, ch_marks,
               un_marks, out_moved):
    """Shift the scan's flags into the buffers, changed flags first:
    ``hist = ((hist << 1) | flag) & mask``, and clear the scan's marks. ``out_moved`` gets each
    cell whose count n_c changed, as ``idx``, or as ``-1 - idx`` when n_c crossed the
    threshold (its neighbours' support changed too). Returns the count written."""
    n = 0
    for k in range(n_changed + n_unchanged):
        if k < n_changed:
            idx, flag = changed[k], 1
            ch_marks[idx >> 3] = 0
        else:
            idx, flag = unchanged[k - n_changed], 0
            un_marks[idx >> 3] = 0
        old = hist[idx]
        if old == 0 and flag == 0:
            continue            # an unchanged flag into an all-unchanged buffer: no change
        new = ((old << 1) | flag) & mask
        hist[idx] = new
        p_old, p_new = popcount16(old), popcount16(new)
        if p_old != p_new:
            crossed = (p_old >= threshold) != (p_new >= threshold)
            out_moved[n] = -1 - idx if crossed else idx
            n += 1
    return n


@njit(cache=True)
def decide_cell(hist, ref, decided, idx, width, mask, threshold, support):
    """Apply the decision rule to cell ``idx`` (flat arrays) and update its decided bit: changed
    when n_c >= T, or, with ``support``, when n_c plus its 8-neighbours of the same two-state
    (free / occupied-or-unknown) in ``ref`` with n >= T reaches T. Returns +1, -1 or 0, the
    change of the number of changed cells."""
    n = popcount16(hist[idx] & mask)
    changed = n >= threshold
    if not changed and support:
        height = ref.shape[0] // width
        row, col = idx // width, idx % width
        occ = ref[idx] != FREE
        for rr in range(max(row - 1, 0), min(row + 2, height)):
            for cc in range(max(col - 1, 0), min(col + 2, width)):
                j = rr * width + cc
                if j != idx and (ref[j] != FREE) == occ and popcount16(hist[j] & mask) >= threshold:
                    n += 1
        changed = n >= threshold
    if changed == (bit_get(decided, idx) == 1):
        return 0
    decided[idx >> 3] = decided[idx >> 3] ^ (1 << (idx & 7))
    return 1 if changed else -1


@njit(cache=True)
def decide(hist, ref, decided, moved, n_moved, width, mask, threshold, support):
    """Re-decide every cell whose own count moved, and the 8-neighbours of those whose count
    crossed the threshold: no other cell's inputs changed. Returns the change of the number of
    changed cells."""
    height = ref.shape[0] // width
    delta = 0
    for k in range(n_moved):
        idx = moved[k] if moved[k] >= 0 else -1 - moved[k]
        delta += decide_cell(hist, ref, decided, idx, width, mask, threshold, support)
        if moved[k] >= 0 or not support:
            continue
        row, col = idx // width, idx % width
        for rr in range(max(row - 1, 0), min(row + 2, height)):
            for cc in range(max(col - 1, 0), min(col + 2, width)):
                if rr != row or cc != col:
                    delta += decide_cell(hist, ref, decided, rr * width + cc, width, mask,
                                         threshold, support)
    return delta


@njit(cache=True)
def decide_all(hist, ref, decided, width, mask, threshold, support):
    """The decision rule over the whole map (on loading a saved state, and in tests)."""
    total = 0
    for idx in range(ref.shape[0]):
        total += decide_cell(hist, ref, decided, idx, width, mask, threshold, support)
    return total


# --- output and last check --------------------------------------------------------------------
@njit(cache=True)
def apply_changes(ref, decided, enclosed, width, close, out):
    """``out`` (a copy of ``ref``, flat) gets the changed cells flipped: free -> occupied,
    occupied or unknown -> free. With ``close``, the last check: each 8-neighbour of a cell
    that became free that lies in an enclosed unknown region of ``ref`` and is itself unchanged
    (so still unknown) becomes occupied. Returns the count of cells the last check closed."""
    height = ref.shape[0] // width
    closed = 0
    for b in range(decided.shape[0]):
        if decided[b] == 0:
            continue
        for idx in range(b * 8, min(b * 8 + 8, ref.shape[0])):
            if not bit_get(decided, idx):
                continue
            out[idx] = OCC if ref[idx] == FREE else FREE
            if not close or ref[idx] == FREE:
                continue
            row, col = idx // width, idx % width
            for rr in range(max(row - 1, 0), min(row + 2, height)):
                for cc in range(max(col - 1, 0), min(col + 2, width)):
                    j = rr * width + cc
                    if bit_get(enclosed, j) and not bit_get(decided, j) and out[j] != OCC:
                        out[j] = OCC
                        closed += 1
    return closed


# --- enclosed unknown regions of the reference map (once per map) -----------------------------
@njit(cache=True)
def unknown_runs(ref, out_row, out_c0, out_c1):
    """Runs of unknown cells, row by row (c1 inclusive). Writes as many as fit and returns
    how many there are (call with empty arrays to count)."""
    n = 0
    cap = out_row.shape[0]
    for row in range(ref.shape[0]):
        col = 0
        width = ref.shape[1]
        while col < width:
            if ref[row, col] >= 0:
                col += 1
                continue
            c0 = col
            while col < width and ref[row, col] < 0:
                col += 1
            if n < cap:
                out_row[n], out_c0[n], out_c1[n] = row, c0, col - 1
            n += 1
    return n


@njit(cache=True)
def link_runs(row, c0, c1, parent):
    """Union-find over runs: runs in adjacent rows that touch, corners included (8-connected
    unknown regions), share a root. Runs are in row order, sorted by column within a row."""
    n = row.shape[0]
    for k in range(n):
        parent[k] = k
    prev0, prev1 = 0, 0        # runs of the previous row: [prev0, prev1)
    k = 0
    while k < n:
        cur0 = k
        while k < n and row[k] == row[cur0]:
            k += 1
        i, j = prev0, cur0
        if prev1 > prev0 and row[prev0] == row[cur0] - 1:
            while i < prev1 and j < k:
                if c0[i] <= c1[j] + 1 and c0[j] <= c1[i] + 1:
                    a, b = find_root(parent, i), find_root(parent, j)
                    parent[max(a, b)] = min(a, b)
                if c1[i] < c1[j]:
                    i += 1
                else:
                    j += 1
        prev0, prev1 = cur0, k


@njit(cache=True)
def mark_enclosed(row, c0, c1, parent, height, width, max_cells, bits):
    """Set the bits of the cells of every unknown region that touches no map border and has at
    most ``max_cells`` cells. Returns the count of cells marked."""
    n = row.shape[0]
    size = np.zeros(n, np.int64)
    border = np.zeros(n, np.bool_)
    for k in range(n):
        root = find_root(parent, k)
        size[root] += c1[k] - c0[k] + 1
        if row[k] == 0 or row[k] == height - 1 or c0[k] == 0 or c1[k] == width - 1:
            border[root] = True
    marked = 0
    for k in range(n):
        root = find_root(parent, k)
        if border[root] or size[root] > max_cells:
            continue
        for col in range(c0[k], c1[k] + 1):
            test_and_set(bits, row[k] * width + col)
        marked += c1[k] - c0[k] + 1
    return marked
