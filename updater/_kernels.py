"""numba kernels of the map updater. Arrays and scalars only; each is called once per scan.

Units: points are in grid units, (gx, gy) = ((x - ox) / res, (y - oy) / res), so a point lies in
cell (row, col) = (floor(gy), floor(gx)); hit points and expected points are (N, 2) arrays of
such points. Per-beam distances arrive in grid units, computed by the caller from the
configuration; walks run from the sensor to a fraction (``reach``) of the way to a hit. Cells
are addressed by their flat index ``row * width + col``. Per-scan marks and the decided state
are bit planes: one bit per cell, packed eight to a byte (``bits[idx >> 3] >> (idx & 7)``).
"""

import math

import numpy as np
from numba import njit, types
from numba.extending import intrinsic

from gridmap._kernels import (NO_HIT, clear_exit, find_root, first_blocked,
                              segment_start, steps_to, traverse)
from gridmap.cells import FREE, OCCUPIED, UNKNOWN

from .hit_tiles import TILE_SHIFT as HIT_TILE_SHIFT
from .verdicts import BeamVerdict

# The blocks of ``clear_blocks`` (gridmap): 8 x 8 cells, 1/64 byte a cell. Here, not in gridmap:
# numba compiles it in, and a cached kernel is compiled again only when its own file changes.
CLEAR_SHIFT = 3

# The per-beam verdicts as plain ints, which numba compiles in as constants.
INVALID = int(BeamVerdict.INVALID)
UNCHANGED = int(BeamVerdict.UNCHANGED)
SKIPPED = int(BeamVerdict.SKIPPED)
CHANGE = int(BeamVerdict.CHANGE)
HIT_TILE_MASK = (1 << HIT_TILE_SHIFT) - 1


# --- bits and counts --------------------------------------------------------------------------
@njit(cache=True, inline="always")
def bit_get(bits, idx):
    """The bit of cell ``idx``."""
    return (bits[idx >> 3] >> (idx & 7)) & 1


@njit(cache=True, inline="always")
def test_and_set(bits, idx):
    """Set the bit of cell ``idx``; False if it was already set."""
    b = idx >> 3
    m = 1 << (idx & 7)
    if bits[b] & m:
        return False
    bits[b] = bits[b] | m
    return True


@njit(cache=True, inline="always")
def set_bit(bits, idx, value):
    """Set cell ``idx``'s bit to ``value``."""
    b = idx >> 3
    bits[b] = (bits[b] & ~np.uint8(1 << (idx & 7))) | np.uint8(np.int64(value) << (idx & 7))


@njit(cache=True)
def clear_bits(bits, cells, n):
    """Clear the bits of the first ``n`` listed cells, and only those."""
    for k in range(n):
        idx = cells[k]
        bits[idx >> 3] = bits[idx >> 3] & ~(1 << (idx & 7))


@intrinsic
def _ctpop64(typingctx, x):
    """The processor's population count of an int64 (LLVM's ctpop)."""
    sig = types.int64(types.int64)

    def codegen(context, builder, signature, args):
        return builder.ctpop(args[0])

    return sig, codegen


@njit(cache=True)
def popcount16(v):
    """The number of set bits of a uint16."""
    return _ctpop64(np.int64(v) & 0xFFFF)


# A cell's flag count lives in a uint8 array of its own (``shift`` 0) or in the bits of its
# buffer above the flags (``shift`` = N_b): the spare bits of a short buffer hold it for free.
@njit(cache=True, inline="always")
def flag_count(hist, seen, idx, shift):
    """The flags cell ``idx`` ever got, saturating (0 when they are not counted). The count
    saturates at its field's largest value (255 in the array of its own), where the rule reads
    it as 'many'."""
    if shift > 0:
        return np.int64(hist[idx]) >> shift
    if seen.shape[0] == 0:
        return 0
    return np.int64(seen[idx])


# --- 1. beam classifier -----------------------------------------------------------------------
@njit(cache=True)
def valid_ranges(ranges, r_lo, r_hi, out_r, out_valid):
    """A beam is valid when its range r [m] is finite, r > 0 (r = 0 is no hit), r >= r_lo and
    r < r_hi. ``out_r`` gets the ranges as float64, NaN for invalid beams."""
    for i in range(ranges.shape[0]):
        r = np.float64(ranges[i])
        ok = np.isfinite(r) and r > 0.0 and r >= r_lo and r < r_hi
        out_valid[i] = ok
        out_r[i] = r if ok else np.nan


@njit(cache=True)
def beam_directions(yaw, angle_min, step, out):
    """(cos, sin) of beam j at ``yaw + angle_min + j * step`` [rad], for every row of ``out``."""
    for j in range(out.shape[0]):
        a = yaw + angle_min + j * step
        out[j, 0] = np.cos(a)
        out[j, 1] = np.sin(a)


@njit(cache=True)
def beam_endpoints(ranges, valid, sensor, directions, res, out_hits):
    """Hit points of the valid beams: the sensor (gx, gy) plus ``ranges`` [m] / ``res`` along
    ``directions``; NaN for invalid beams. Returns (valid beams, the summed lengths of their
    walks in cells, the cell count of the box around the sensor and the hits): bounds on the
    cells any evaluator can flag."""
    gx0, gy0 = sensor[0], sensor[1]
    c0, r0 = int(np.floor(gx0)), int(np.floor(gy0))
    c_lo, c_hi, r_lo, r_hi = c0, c0, r0, r0
    n_valid = 0
    walk = 0
    for i in range(ranges.shape[0]):
        if not valid[i]:
            out_hits[i, 0] = out_hits[i, 1] = np.nan
            continue
        hx = gx0 + ranges[i] / res * directions[i, 0]
        hy = gy0 + ranges[i] / res * directions[i, 1]
        out_hits[i, 0] = hx
        out_hits[i, 1] = hy
        n_valid += 1
        c, rw = int(np.floor(hx)), int(np.floor(hy))
        walk += abs(c - c0) + abs(rw - r0) + 7
        c_lo, c_hi = min(c_lo, c), max(c_hi, c)
        r_lo, r_hi = min(r_lo, rw), max(r_hi, rw)
    return n_valid, walk, (c_hi - c_lo + 3) * (r_hi - r_lo + 3)


@njit(cache=True)
def cast_virtual(ref, clear, sensor, directions, max_len, out_expected, out_found):
    """Cast the virtual beams once: beam j from the sensor along ``directions[j]`` ends at the
    first occupied-or-unknown cell of ``ref``, or where it leaves the map (outside is unknown);
    ``out_found[j]`` is False when nothing blocks it within ``max_len`` grid units. ``clear``:
    ``clear_blocks`` of ``ref`` (blocks of 2**CLEAR_SHIFT cells), crossed in jumps."""
    gx0, gy0 = sensor[0], sensor[1]
    for j in range(directions.shape[0]):
        ca, sa = directions[j, 0], directions[j, 1]
        t, status = first_blocked(ref, clear, CLEAR_SHIFT, gx0, gy0, ca, sa, max_len)
        out_found[j] = status != NO_HIT
        out_expected[j, 0] = gx0 + t * ca
        out_expected[j, 1] = gy0 + t * sa


@njit(cache=True)
def classify(hits, valid, pairing, expected, found, half_window, wrap, out_change):
    """A valid beam i is a detected change when no expected point in the window of virtual
    beams ``i * ratio +- half_window`` (ratio: virtual beams per measured beam) lies closer
    than ``pairing[i]`` (D(r_i), grid units) to its hit point. The window is searched nearest
    index first and wraps around the ends only when ``wrap``. Returns the count of changes."""
    n, m = hits.shape[0], expected.shape[0]
    ratio = m // n if n else 1
    n_change = 0
    for i in range(n):
        out_change[i] = False
        if not valid[i]:
            continue
        d2 = pairing[i] * pairing[i]
        found_near = False
        for k in range(2 * half_window + 1):
            j = i * ratio + ((k + 1) // 2 if k % 2 == 1 else -(k // 2))
            if wrap:
                j = j % m
            elif j < 0 or j >= m:
                continue
            dx, dy = hits[i, 0] - expected[j, 0], hits[i, 1] - expected[j, 1]
            if found[j] and dx * dx + dy * dy < d2:
                found_near = True
                break
        if not found_near:
            out_change[i] = True
            n_change += 1
    return n_change


@njit(cache=True)
def run_filter(change, min_run, wrap, out_keep, hits, min_width=0.0):
    """Keep a change only inside a run of at least ``min_run`` consecutive changes (a beam that
    is not a change, invalid ones included, ends a run), or, with ``min_width`` > 0 [cells],
    of at least two whose first and last ``hits`` lie that far apart. With ``wrap`` a run may
    cross the scan's ends. Returns the count kept."""
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
            if n >= min_run or (min_width > 0.0 and n >= 2):
                out_keep[:] = True
                return n
            return 0
    kept = 0
    run = 0
    for k in range(n + 1):
        if k < n and change[(start + k) % n]:
            run += 1
            continue
        wide = False
        if min_width > 0.0 and 2 <= run < min_run:
            a, b = (start + k - run) % n, (start + k - 1) % n
            wide = math.hypot(hits[a, 0] - hits[b, 0], hits[a, 1] - hits[b, 1]) >= min_width
        if run >= min_run or wide:
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


# --- the classifier in two calls -------------------------------------------------------------
# The range-dependent distances' parameters, in this order, as ``UpdaterConfig`` names them.
DISTANCES = ("pairing_distance_near", "pairing_range_near", "pairing_distance_slope",
             "pairing_distance_max", "radius_near", "radius_far", "radius_far_range",
             "removed_skip_fraction", "removed_skip_min", "free_fraction", "removed_skip_across")
# The smallest sine of the angle between a beam and the surface it hits that ``skip_across``
# divides by: a beam that grazes a surface more closely walks no less than a tenth of the way.
MIN_INCIDENCE_SINE = 0.1


@njit(cache=True)
def beam_distances(ranges, res, dist, out_pairing, out_tol, out_skip, out_reach,
                   out_free_reach):
    """The distances of ``UpdaterConfig.pairing_distance``, ``new_obstacle_radius`` and
    ``removed_skip`` for every range [m] (NaN for NaN), the same operations in the same order,
    so the same bits: D(r) and tol(r) in grid units, the skip in metres, the removed-obstacle
    walk's reach ``1 - skip / r``, and ``free_fraction`` for every free walk's reach. ``dist``
    holds the parameters in the order of ``DISTANCES``."""
    for i in range(ranges.shape[0]):
        r = ranges[i]
        out_pairing[i] = np.minimum(dist[0] + dist[2] * (r - dist[1]), dist[3]) / res
        frac = np.minimum(r / dist[6], 1.0)
        out_tol[i] = (dist[4] + (dist[5] - dist[4]) * frac) / res
        skip = np.maximum(dist[7] * r, dist[8])
        out_skip[i] = skip
        out_reach[i] = 1.0 - skip / r
        out_free_reach[i] = dist[9]


@njit(cache=True)
def prepare_beams(ranges, r_lo, r_hi, sensor, angle_min, step, increment, ratio, res, dist,
                  out_r, out_valid, out_virtual, out_measured, out_hits, out_pairing, out_tol,
                  out_skip, out_reach, out_free_reach):
    """The classifier's per-beam inputs in one call: ``valid_ranges``, the directions of the
    virtual beams (``step`` apart from ``angle_min``) and, when there are ``ratio`` > 1 per
    measured beam, of the measured ones (``increment`` apart), ``beam_endpoints`` and
    ``beam_distances``. Returns (valid beams, a bound on the cells any evaluator can flag)."""
    valid_ranges(ranges, r_lo, r_hi, out_r, out_valid)
    beam_directions(sensor[2], angle_min, step, out_virtual)
    measured = out_virtual      # one virtual beam per step: the very same angles
    if ratio != 1:
        beam_directions(sensor[2], np.float64(angle_min), np.float64(increment), out_measured)
        measured = out_measured
    n_valid, walked, box = beam_endpoints(out_r, out_valid, sensor, measured, res, out_hits)
    beam_distances(out_r, res, dist, out_pairing, out_tol, out_skip, out_reach, out_free_reach)
    if dist[10] > 0.0:
        skip_across(out_r, out_valid, out_hits, sensor, out_skip, out_reach, ranges.shape[0])
    return n_valid, min(walked, box)


@njit(cache=True)
def skip_across(ranges, valid, hits, sensor, out_skip, out_reach, n):
    """The removed-obstacle skip measured across the surface each beam hits rather than along
    the beam: divided by the sine of the angle between the beam and that surface (the line
    through the hits of the beam's valid neighbours, or of the beam and its one valid
    neighbour), at least ``MIN_INCIDENCE_SINE``. A beam that grazes a wall ends its walk as far
    from the wall as one that meets it square, so a pose a few centimetres off across the wall
    does not walk the beam through the wall's face. A beam with no valid neighbour keeps its
    skip. ``n``: the scan's beams (the first rows of the arrays)."""
    for i in range(n):
        if not valid[i]:
            continue
        a = i - 1 if i > 0 and valid[i - 1] else i
        b = i + 1 if i + 1 < n and valid[i + 1] else i
        if a == b:
            continue
        tx, ty = hits[b, 0] - hits[a, 0], hits[b, 1] - hits[a, 1]
        dx, dy = hits[i, 0] - sensor[0], hits[i, 1] - sensor[1]
        norm = math.sqrt((tx * tx + ty * ty) * (dx * dx + dy * dy))
        if not norm > 0.0:
            continue
        sine = max(abs(dx * ty - dy * tx) / norm, MIN_INCIDENCE_SINE)
        out_skip[i] = out_skip[i] / sine
        reach = 1.0 - out_skip[i] / ranges[i]
        # (a reach within rounding of 0 would put the walk's end on the sensor)
        out_reach[i] = reach if reach > 1e-6 else 0.0


@njit(cache=True)
def classify_scan(ref, clear, sensor, virtual, max_len, hits, valid, pairing, half_window, wrap,
                  min_run, n_skip, out_expected, out_found, out_change, out_keep, out_verdict,
                  min_width=0.0):
    """``cast_virtual``, ``classify``, ``run_filter`` and ``beam_verdicts`` in one call.
    Returns (detected changes, changes kept by the run filter)."""
    cast_virtual(ref, clear, sensor, virtual, max_len, out_expected, out_found)
    raw = classify(hits, valid, pairing, out_expected, out_found, half_window, wrap, out_change)
    kept = run_filter(out_change, min_run, wrap, out_keep, hits, min_width)
    beam_verdicts(valid, out_keep, n_skip, wrap, out_verdict)
    return raw, kept


@njit(cache=True, inline="always")
def ends_in_unknown(ref, expected, directions, i):
    """Whether the expected ray of row ``i`` stops at an unknown cell of ``ref`` (or leaves the
    map, whose outside is unknown). The expected point is where the ray enters that cell: a
    hair (1e-4 grid units) further along lies inside."""
    height, width = ref.shape
    col = int(np.floor(expected[i, 0] + 1e-4 * directions[i, 0]))
    row = int(np.floor(expected[i, 1] + 1e-4 * directions[i, 1]))
    return not (0 <= col < width and 0 <= row < height) or ref[row, col] == UNKNOWN


@njit(cache=True)
def known_changes(ref, expected, directions, found, ranges, change):
    """The lost check's counts, a row per measured beam: (beams with a range whose expected
    ray ends in known space, those of them that are changes)."""
    n_known = n_changes = 0
    for i in range(ranges.shape[0]):
        if np.isnan(ranges[i]) or (found[i] and ends_in_unknown(ref, expected, directions, i)):
            continue
        n_known += 1
        n_changes += change[i] != 0
    return n_known, n_changes


@njit(cache=True)
def scan_is_lost(ref, expected, directions, found, ranges, change, n_valid, raw, lost_fraction):
    """Whether a classified scan is dropped as lost: more than ``lost_fraction`` of its
    ``n_valid`` valid beams are changes (``raw``, before the run filter), the pose is probably
    wrong. A beam that is a change because it looks into unknown space says nothing of the
    pose (docs/algorithm.md, a partly mapped place), so such a scan is dropped only if the
    beams whose expected ray ends in known space are changes past ``lost_fraction`` too
    (``known_changes``). Never more scans than the paper's rule: that is asked first."""
    if not (n_valid > 0 and raw > lost_fraction * n_valid):
        return False
    n_known, n_changes = known_changes(ref, expected, directions, found, ranges, change)
    return n_known > 0 and n_changes > lost_fraction * n_known


# --- walks along beams ------------------------------------------------------------------------
# A walk's cells listed (``walk``), then flagged (``flag_free_listed``, ``flag_occupied_listed``):
# the plain form of what ``walk_beams`` does in one pass, kept to check it against.
@njit(cache=True)
def walk(ref, sensor, hit, reach, drop_last, cells):
    """List in ``cells`` (row 0: rows, row 1: cols) the cells of ``ref`` that the segment from
    the sensor to the point at ``reach`` of the way to ``hit`` passes through, in order,
    clipped to the map; ``drop_last`` leaves out the cell holding that end point when it lies
    on the map. Returns the count."""
    height, width = ref.shape
    gx0, gy0 = sensor[0], sensor[1]
    tx = gx0 + reach * (hit[0] - gx0)
    ty = gy0 + reach * (hit[1] - gy0)
    n = traverse(gx0, gy0, tx, ty, height, width, cells[0], cells[1])
    if drop_last and 0.0 <= tx < width and 0.0 <= ty < height:
        n -= 1
    return n


@njit(cache=True)
def flag_free_listed(ref, cells, count, marks, out, n):
    """Append to ``out`` (from position n) the first ``count`` cells of ``cells`` that are free
    in ``ref`` and not yet marked, and mark them. Returns the new count. Most cells of a free
    walk are free, and about half of them new, so the flag goes in without a branch:
    ``out[n]`` is written for every cell and kept only when the cell is taken (``out`` needs
    one slot to spare)."""
    width = ref.shape[1]
    flat = ref.reshape(-1)
    for k in range(count):
        idx = cells[0, k] * width + cells[1, k]
        b = idx >> 3
        bit = np.uint8(1 << (idx & 7))
        old = marks[b]
        take = (flat[idx] == FREE) & ((old & bit) == 0)
        marks[b] = old | (bit if take else np.uint8(0))
        out[n] = idx
        n += take
    return n


@njit(cache=True)
def flag_occupied_listed(ref, cells, count, marks, out, n):
    """Append to ``out`` (from position n) the first ``count`` cells of ``cells`` that are
    occupied or unknown in ``ref`` and not yet marked, and mark them. Returns the new count."""
    width = ref.shape[1]
    flat = ref.reshape(-1)
    for k in range(count):
        idx = cells[0, k] * width + cells[1, k]
        if flat[idx] != FREE and test_and_set(marks, idx):
            out[n] = idx
            n += 1
    return n


# What a fused walk flags: the free cells, the occupied-or-unknown ones, or the open unknown.
WALK_FREE = 0
WALK_BLOCKED = 1
WALK_OPEN_UNKNOWN = 2
# walk_beams without its shortcuts: the plain walks the fused ones are checked against
NO_BLOCKS = np.zeros((0, 0), np.uint8)
NO_SKIPS = np.zeros(0, np.float64)
NO_ENTRIES = np.zeros((0, 2), np.float64)
# [grid units] a beam's walks that flag no free cell start this far short of where its expected
# ray met a cell that is not free (``walk_scan``): the walk's segment and the ray agree but for
# rounding
ENTRY_MARGIN = 2.0
# ``settled``'s bound past every buffer: none is settled
NEVER_SETTLED = 0x10000


@njit(cache=True)
def walk_beams(ref, enclosed, clear, sensor, hits, reach, select, want, drop_last, cap, kind,
               marks, out, n, skip):
    """``walk`` and the flagging of its cells in one pass, with no list of cells in between,
    for every beam i with ``select[i] == want`` and ``reach[i]`` > 0: append to ``out`` (from
    position n) the cells of its walk (at most ``cap`` of them, as ``walk`` lists at most that
    many) that are of ``kind`` and not yet marked, in the walks' order, and mark them. Returns
    the new count. The cells are those of ``traverse``: the same start, the same steps, the
    same tie-breaking. The flag of a walk through M's obstacles or unknown space goes in
    without a branch (``out[n]`` is written for every cell and kept only when the cell is
    taken, so ``out`` needs one slot to spare); a free walk's behind a branch, as most of its
    cells are marked already when ``marks`` keeps the settled ones (``settled_marks``); and the
    loop over the beams holds the loop over the cells: no call per beam takes an array, each
    of which would cost reference counting.

    Two shortcuts leave the cells flagged as they are. A walk that flags no free cell jumps
    across the square of clear blocks around its first cell (``clear``: ``clear_blocks`` of
    ``ref``; empty: no jump), looked up once a walk: a walk through space M does not know
    would pay for more lookups and gain nothing. A free walk starts ``skip[i]`` grid units
    from the sensor (``free_walk_skips``: cells that other walks of the scan cross; an empty
    ``skip``: none). Past a jump the walk's edges are sums in closed form, which can round
    otherwise in the last bits than stepping: a cell where the segment passes within about
    1e-12 of a corner can differ."""
    height, width = ref.shape
    flat = ref.reshape(-1)
    gx0, gy0 = sensor[0], sensor[1]
    for i in range(hits.shape[0]):
        if select[i] != want or not reach[i] > 0.0:
            continue
        tx = gx0 + reach[i] * (hits[i, 0] - gx0)
        ty = gy0 + reach[i] * (hits[i, 1] - gy0)
        cx, cy, n_x, n_y, step_x, step_y, t_delta_x, t_delta_y, t_max_x, t_max_y = \
            segment_start(gx0, gy0, tx, ty, height, width)
        count = min(n_x + n_y + 1, cap) if n_x >= 0 else 0
        if count > 0 and drop_last and 0.0 <= tx < width and 0.0 <= ty < height:
            count -= 1
        late = skip[i] if skip.shape[0] and count == n_x + n_y + 1 else 0.0
        cx, cy, n_x, n_y, t_max_x, t_max_y, done = _walk_start(
            clear, kind != WALK_FREE, late, gx0, gy0, tx, ty, cx, cy, n_x, n_y, step_x, step_y,
            t_delta_x, t_delta_y, t_max_x, t_max_y)
        count -= done
        n = _walk_cells(flat, enclosed, kind, cy * width + cx, n_x, n_y, count, step_x,
                        step_y * width, t_delta_x, t_delta_y, t_max_x, t_max_y, marks, out, n)
    return n


@njit(cache=True)
def free_walk_skips(sensor, hits, reach, select, want, increment, wrap, cap, out):
    """Per beam i whose free walk runs (as ``walk_beams`` selects them): how far from the
    sensor (grid units) its walk may start and the scan's free walks still flag the very cells
    that walks from the sensor flag. ``increment``: the angle between two beams (0: no
    skips); ``wrap``: the beams cover 360 degrees, beam n following beam n - 1 by that angle.

    Beam i = 2**l * odd lies between beams i - 2**l and i + 2**l, which both rank higher
    (divide by 2**(l+1); beam 0 ranks highest). A cell that i's walk enters within r of the
    sensor has its far corner within r + sqrt(2). Seen from the sensor along direction phi, a
    unit square is w = |cos phi| + |sin phi| wide across, so it spans an angle of about
    w / (r + sqrt(2)) (2 atan(w / 2 rho) exactly, rho its far corner's distance). While that
    exceeds the two beams' spacing s = 2**(l+1) * increment, one of the two crosses the cell
    strictly inside, and flags it if it walks past r + sqrt(2). So i may skip to r when both
    walk that far; by induction from beam 0, which skips nothing, every cell a walk skips is
    flagged by a walk that does not. The width is taken at i's direction less sqrt(2) s (the
    cell's bisector lies within s of it when the span is below 2 s) and at least 1; a tenth
    of the spacing is kept in hand, which also covers atan's shortfall."""
    n = hits.shape[0]
    gx0, gy0 = sensor[0], sensor[1]
    for i in range(n):
        out[i] = 0.0
        if i == 0 or not increment > 0.0 or select[i] != want or not reach[i] > 0.0:
            continue
        low = i & -i
        s = 2 * low * increment
        dx, dy = hits[i, 0] - gx0, hits[i, 1] - gy0
        # sqrt, not hypot (several times slower): the bounds keep a margin far above a bit
        w = max(1.0, (abs(dx) + abs(dy)) / max(math.sqrt(dx * dx + dy * dy), 1e-300) - 1.5 * s)
        r = 0.9 * w / s - 1.5
        for j in (i - low, i + low):
            if j >= n:
                j = j - n if wrap else -1
            if j < 0 or (j != 0 and (j & -j) <= low) or select[j] != want \
                    or not reach[j] > 0.0:
                r = 0.0
                break
            ex, ey = hits[j, 0] - gx0, hits[j, 1] - gy0
            length = reach[j] * math.sqrt(ex * ex + ey * ey)
            if 2.0 * length + 4.0 > cap:
                r = 0.0
                break
            r = min(r, length - 1.5)
        out[i] = max(r, 0.0)


@njit(cache=True, inline="always")
def _walk_start(clear, jumps, late, gx0, gy0, tx, ty, cx, cy, n_x, n_y, step_x, step_y,
                t_delta_x, t_delta_y, t_max_x, t_max_y):
    """Where a walk from (gx0, gy0) to (tx, ty), at cell (cx, cy), begins flagging: past the
    square of clear blocks around it (``jumps``, a walk that flags no free cell), and at least
    ``late`` grid units from the sensor (a free walk's ``free_walk_skips``, or where a walk
    into unknown space meets it; 0: none). Returns the walk's state there and the cells
    passed over: (cx, cy, n_x, n_y, t_max_x, t_max_y, passed)."""
    p = -1.0
    if jumps and clear.shape[0] > 0:
        # the square of clear blocks around the sensor, with a margin inside it: the jump's
        # closed-form sums may round either way
        p = min(clear_exit(clear, CLEAR_SHIFT, cx, cy, gx0, gy0, step_x, step_y, t_delta_x,
                           t_delta_y), 1.0) - 1e-9
    if late > 0.0:
        p = max(p, min(late / math.sqrt((tx - gx0) ** 2 + (ty - gy0) ** 2), 1.0 - 1e-9))
    if not (p > t_max_x or p > t_max_y):
        return cx, cy, n_x, n_y, t_max_x, t_max_y, 0
    kx, ky = steps_to(p, t_max_x, t_max_y, t_delta_x, t_delta_y)
    kx, ky = min(kx, n_x), min(ky, n_y)
    return (cx + kx * step_x, cy + ky * step_y, n_x - kx, n_y - ky, t_max_x + kx * t_delta_x,
            t_max_y + ky * t_delta_y, kx + ky)


@njit(cache=True, inline="always")
def _next_cell(idx, n_x, n_y, t_max_x, t_max_y, step_x, row_step, t_delta_x, t_delta_y):
    """One step of a walk (``traverse``'s, on flat indices): the x edge first on a tie, and
    only the steps left along each axis."""
    go_x = n_x > 0 and (n_y == 0 or t_max_x <= t_max_y)
    return (idx + (step_x if go_x else row_step), n_x - (1 if go_x else 0),
            n_y - (0 if go_x else 1), t_max_x + t_delta_x if go_x else t_max_x,
            t_max_y if go_x else t_max_y + t_delta_y)


@njit(cache=True, inline="always")
def _walk_cells(flat, enclosed, kind, idx, n_x, n_y, count, step_x, row_step, t_delta_x,
                t_delta_y, t_max_x, t_max_y, marks, out, n):
    """``count`` cells of a walk from cell ``idx``: flag those of ``kind`` not yet marked."""
    return _walk_cells_on(flat, enclosed, kind, idx, n_x, n_y, count, step_x, row_step,
                          t_delta_x, t_delta_y, t_max_x, t_max_y, marks, out, n)[0]


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
def flag_removed_obstacles(ref, sensor, hits, reach, verdict, marks, cells, out):
    """Removed obstacles: the occupied-or-unknown cells from the sensor to p_th of each CHANGE
    beam i, all but the last, where p_th lies ``reach[i]`` of the way to the hit (none when
    ``reach[i]`` <= 0: the skip reaches back to the sensor); each cell once (``marks``: cells
    marked already, as seen surfaces are, get no flag). Returns the count."""
    return walk_beams(ref, marks, NO_BLOCKS, sensor, hits, reach, select=verdict, want=CHANGE,
                      drop_last=True, cap=cells.shape[1], kind=WALK_BLOCKED, marks=marks, out=out,
                      n=0, skip=NO_SKIPS)


@njit(cache=True)
def flag_new_obstacles(ref, hits, tol, verdict, marks, out, n, new=None):
    """New obstacles: the hit cell of each CHANGE beam i, if every cell of ``ref`` within
    ``tol[i]`` (tol(r_i), grid units) of the hit is free, appended to ``out`` from position n;
    each cell once (``marks``). ``new``: which beams are such, worked out already
    (``unmark_changing``). Returns the new count."""
    for i in range(hits.shape[0]):
        if verdict[i] != CHANGE:
            continue
        if not (new[i] if new is not None else disc_is_free(ref, hits[i, 0], hits[i, 1],
                                                            tol[i])):
            continue
        idx = hit_cell(ref, hits[i, 0], hits[i, 1])
        if idx >= 0 and test_and_set(marks, idx):     # off the map only with tol 0
            out[n] = idx
            n += 1
    return n


@njit(cache=True)
def unmark_changing(ref, hits, tol, verdict, gaps, ch_marks, un_marks, out_new):
    """Clear the unchanged-flag marks (``un_marks``, set between scans on the free cells whose
    buffers are settled: ``settled_marks``) of the free cells that take a changed flag this
    scan, before the walks: the new-obstacle flags (``flag_new_obstacles``, with the seen
    surfaces' marks in ``ch_marks``) and the ``fill_gaps`` flags (``gaps`` > 0: the clearance
    of ``flag_gaps``, which flags each such cell that is not a new obstacle). Those flags come
    after the walks, and after a changed flag an unchanged one counts. ``out_new`` gets which
    beams are new obstacles, for ``flag_new_obstacles``."""
    for i in range(hits.shape[0]):
        new = verdict[i] == CHANGE and disc_is_free(ref, hits[i, 0], hits[i, 1], tol[i])
        out_new[i] = new
        gap = verdict[i] == UNCHANGED and gaps > 0 and \
            square_is_free(ref, hits[i, 0], hits[i, 1], gaps)
        if not (new or gap):
            continue
        idx = hit_cell(ref, hits[i, 0], hits[i, 1])
        if idx >= 0 and (verdict[i] == UNCHANGED or not bit_get(ch_marks, idx)):
            set_bit(un_marks, idx, False)


# --- seen-surface guard (not in the paper) ----------------------------------------------------
@njit(cache=True)
def mark_seen_surfaces(ref, enclosed, hits, verdict, radius, unknown_radius, marks, out,
                       need=None):
    """Mark (in ``marks``, so the removed-obstacle walk passes them by) the cells of ``ref``
    that come within ``radius`` (grid units) of the hit point of any valid beam and are
    occupied, or within ``unknown_radius`` and unknown outside the ``enclosed`` regions, and
    list them in ``out``. Enclosed unknown cells (an object's interior) are left to the walk: a
    hit near one is on the face of whatever still stands beside it, and the last check closes
    what stays unknown next to a freed cell. ``need``: only the hits of the beams it selects
    (``guard_needed``). Returns the count listed."""
    height, width = ref.shape
    flat = ref.reshape(-1)
    n = 0
    last = out.shape[0] - 1     # each cell visited is written there, and counted if marked
    if last < 0:
        return 0
    r2 = radius * radius
    u2 = unknown_radius * unknown_radius
    for i in range(hits.shape[0]):
        if verdict[i] == INVALID or (need is not None and not need[i]):
            continue
        x, y = hits[i, 0], hits[i, 1]
        c0, c1 = max(int(np.floor(x - radius)), 0), min(int(np.floor(x + radius)) + 1, width)
        for row in range(max(int(np.floor(y - radius)), 0),
                         min(int(np.floor(y + radius)) + 1, height)):
            dy = max(row - y, 0.0, y - row - 1.0)
            for idx in range(row * width + c0, row * width + c1):
                v = flat[idx]
                if v == FREE:
                    continue
                # no branch on the others: which of them to mark is anyone's guess
                col = idx - row * width
                dx = max(col - x, 0.0, x - col - 1.0)
                occupied = v == OCCUPIED
                take = (dx * dx + dy * dy <= (r2 if occupied else u2)) & \
                    (occupied | (bit_get(enclosed, idx) == 0))
                b, bit = idx >> 3, np.uint8(1 << (idx & 7))
                old = marks[b]
                marks[b] = old | (bit if take else np.uint8(0))
                out[min(n, last)] = idx
                n += take & ((old & bit) == 0)
    return n


@njit(cache=True)
def guard_needed(sensor, hits, verdict, removed_select, removed_reach, into, unknown_reach,
                 radius, increment, out):
    """Which valid beams' hits the seen-surface guard needs (``out``), as ``walk_scan`` walks:
    those near a walk that flags changed cells (a removed-obstacle walk, ``removed_select``
    CHANGE with ``removed_reach`` > 0, or a walk into unknown space, ``into`` with
    ``unknown_reach`` > 0). The guard's marks matter to those walks alone. A cell that beam
    i's walk crosses has its centre within sqrt(2) / 2 of i's ray, and a guarded cell has it
    within ``radius`` + sqrt(2) / 2 of the hit; so the hit of beam j, R from the sensor, can
    guard a cell of i's walk only if i's ray passes within rho = ``radius`` + sqrt(2) of it:
    R <= rho, or R sin(a) <= rho for the angle a <= pi / 2 between the two beams. Beam j
    lies at j ``increment`` from beam 0, modulo a turn (the scan may cover a turn or more);
    the angle is taken to the nearest such walk, less one beam in hand. ``increment`` 0, or
    walks from a quarter of the beams or more: every valid beam's hit. Returns the count."""
    n = hits.shape[0]
    before = np.empty(n, np.int64)      # the last beam at or before i whose walk flags changed
    after = np.empty(n, np.int64)       # ... the first at or after i; -1: none
    last = -1
    walking = 0
    for i in range(n):
        if (removed_select[i] == CHANGE and removed_reach[i] > 0.0) or \
                (into[i] and unknown_reach[i] > 0.0):
            last = i
            walking += 1
        before[i] = last
    last = -1
    for i in range(n - 1, -1, -1):
        last = i if before[i] == i else last
        after[i] = last
    rho2 = (radius + math.sqrt(2.0) + 1e-6) ** 2
    # with walks from a quarter of the beams or more, few hits are far from all of them
    every = not increment > 0.0 or 4 * walking >= n
    turn = 2.0 * math.pi / increment if increment > 0.0 else 0.0    # beams per turn
    # the nearest walk lies within half a turn of j + m turn: |m| <= (n - 1) / turn + 1 / 2
    turns = int((n - 1) / turn + 0.5) if 0.0 < turn < 2.0 * n else 0
    count = 0
    for j in range(n):
        need = False
        if verdict[j] != INVALID and walking > 0:
            dx, dy = hits[j, 0] - sensor[0], hits[j, 1] - sensor[1]
            r2 = dx * dx + dy * dy
            need = every or r2 <= rho2
            gap = np.inf                # [beams] to the nearest walk, turns apart counted
            for t in range(0 if need else 2 * turns + 1):      # m = 0, 1, -1, 2, -2 ...
                p = j + ((t + 1) // 2) * (1 - 2 * (t % 2 == 0)) * turn
                if max(-p, p - (n - 1)) >= gap:
                    continue
                lo, hi = min(int(math.floor(p)), n - 1), max(int(math.ceil(p)), 0)
                if lo >= 0 and before[lo] >= 0:
                    gap = min(gap, p - before[lo])
                if hi <= n - 1 and after[hi] >= 0:
                    gap = min(gap, after[hi] - p)
            a = max(gap - 1.0, 0.0) * increment
            # sin(a) >= 2 a / pi: most beams are told apart without a sine
            if not need and a <= 0.5 * math.pi and r2 * (a / (0.5 * math.pi)) ** 2 <= rho2:
                need = r2 * math.sin(a) ** 2 <= rho2
        out[j] = need
        count += need
    return count


# --- fill_gaps (not in the paper) -------------------------------------------------------------
@njit(cache=True)
def flag_gaps(ref, hits, verdict, clearance, marks, out, n):
    """Changed flags, appended to ``out`` from position n, for the hit cells of UNCHANGED beams
    whose square of ``clearance`` cells each way is free in ``ref`` (a surface where M has
    nothing that near); each cell once (``marks``). Returns the new count."""
    for i in range(hits.shape[0]):
        if verdict[i] != UNCHANGED or not square_is_free(ref, hits[i, 0], hits[i, 1],
                                                         clearance):
            continue
        idx = hit_cell(ref, hits[i, 0], hits[i, 1])
        if test_and_set(marks, idx):
            out[n] = idx
            n += 1
    return n


@njit(cache=True, inline="always")
def hit_cell(ref, px, py):
    """The flat index of the cell of point (px, py), -1 when it lies off the map."""
    height, width = ref.shape
    if not (0.0 <= px < width and 0.0 <= py < height):
        return -1
    return int(np.floor(py)) * width + int(np.floor(px))


@njit(cache=True)
def square_is_free(ref, px, py, k):
    """True when the square of k cells each way around the cell of (px, py) lies on the map and
    is all free in ``ref``."""
    height, width = ref.shape
    row0 = int(np.floor(py))
    col0 = int(np.floor(px))
    if row0 < k or row0 >= height - k or col0 < k or col0 >= width - k:
        return False
    for dr in range(-k, k + 1):
        for dc in range(-k, k + 1):
            if ref[row0 + dr, col0 + dc] != FREE:
                return False
    return True


# --- 3. unchanged-cells evaluator -------------------------------------------------------------
@njit(cache=True)
def flag_free_unchanged(ref, sensor, hits, reach, verdict, marks, cells, out):
    """Free: the free cells of ``ref`` from the sensor to ``reach[i]`` of the way to the hit of
    each UNCHANGED beam i; each cell once (``marks``). Returns the count."""
    return walk_beams(ref, marks, NO_BLOCKS, sensor, hits, reach, select=verdict, want=UNCHANGED,
                      drop_last=False, cap=cells.shape[1], kind=WALK_FREE, marks=marks, out=out,
                      n=0, skip=NO_SKIPS)


@njit(cache=True)
def flag_occupied_unchanged(ref, hits, verdict, marks, out, n):
    """Occupied: every occupied-or-unknown cell of ``ref`` among the hit cell of each
    UNCHANGED beam and its 4-neighbours, appended to ``out`` from position n; each cell once
    (``marks``). Returns the new count."""
    height, width = ref.shape
    for i in range(hits.shape[0]):
        if verdict[i] != UNCHANGED:
            continue
        row0 = int(np.floor(hits[i, 1]))
        col0 = int(np.floor(hits[i, 0]))
        for dr, dc in ((0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)):
            row, col = row0 + dr, col0 + dc
            if 0 <= row < height and 0 <= col < width and ref[row, col] != FREE:
                if test_and_set(marks, row * width + col):
                    out[n] = row * width + col
                    n += 1
    return n


# --- hits confirm M's surfaces (not in the paper) ---------------------------------------------
@njit(cache=True)
def flag_hit_surfaces(ref, hits, verdict, marks, out, n):
    """Unchanged flags, appended to ``out`` from position n, for the occupied cells of ``ref``
    among the hit cell and its 4-neighbours of each CHANGE or SKIPPED beam whose hit cell lies
    on the map and is not free in ``ref``; each cell once (``marks``, shared with the
    unchanged-cells evaluator). Returns the new count."""
    height, width = ref.shape
    for i in range(hits.shape[0]):
        if verdict[i] != CHANGE and verdict[i] != SKIPPED:
            continue
        row0 = int(np.floor(hits[i, 1]))
        col0 = int(np.floor(hits[i, 0]))
        if not (0 <= row0 < height and 0 <= col0 < width) or ref[row0, col0] == FREE:
            continue
        for dr, dc in ((0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)):
            row, col = row0 + dr, col0 + dc
            if 0 <= row < height and 0 <= col < width and ref[row, col] == OCCUPIED:
                if test_and_set(marks, row * width + col):
                    out[n] = row * width + col
                    n += 1
    return n


# --- growth into the unknown (not in the paper) -----------------------------------------------
@njit(cache=True, inline="always")
def is_open_unknown(ref_flat, enclosed, idx):
    """Unknown in M and outside the enclosed regions: space M never saw, where the map grows
    (an enclosed region is an object's interior, which the last check closes)."""
    v = ref_flat[idx]
    return v != FREE and v != OCCUPIED and not bit_get(enclosed, idx)


@njit(cache=True)
def list_unknown_hits(ref, enclosed, hits, verdict, hit_marks, ch_marks, out):
    """The hit cells of valid beams in open unknown space, each once (``hit_marks``), into
    ``out``; their changed-flag marks are set too, so that no walk of the scan flags the cells
    it hits (``clear_bits`` clears them after the walks). Returns the count."""
    height, width = ref.shape
    flat = ref.reshape(-1)
    n = 0
    for i in range(hits.shape[0]):
        if verdict[i] == INVALID:
            continue
        row, col = int(np.floor(hits[i, 1])), int(np.floor(hits[i, 0]))
        if not (0 <= row < height and 0 <= col < width):
            continue
        idx = row * width + col
        if is_open_unknown(flat, enclosed, idx) and test_and_set(hit_marks, idx):
            ch_marks[idx >> 3] = ch_marks[idx >> 3] | (1 << (idx & 7))
            out[n] = idx
            n += 1
    return n


@njit(cache=True)
def flag_open_unknown_walks(ref, enclosed, sensor, hits, reach, into_unknown, marks, cells,
                            out, n):
    """Changed flags, appended to ``out`` from position n, for the open unknown cells from the
    sensor to ``reach[i]`` of the way to the hit of each beam i that looks into unknown space
    (``into_unknown[i]``), all but the last; each cell once (``marks``). Returns the new
    count."""
    return walk_beams(ref, enclosed, NO_BLOCKS, sensor, hits, reach, select=into_unknown,
                      want=True, drop_last=True, cap=cells.shape[1], kind=WALK_OPEN_UNKNOWN,
                      marks=marks, out=out, n=n, skip=NO_SKIPS)


@njit(cache=True)
def flag_unknown_seen_through(ref, enclosed, clear, sensor, hits, ranges, expected, directions,
                              found, short, marks, cap, into, reach, out, n):
    """``flag_open_unknown_walks`` for the valid beams whose expected ray ends at an unknown
    cell (``ends_in_unknown`` of their ``expected`` point, ``directions`` and ``found``, one
    row per beam), each walking to ``short`` [m] short of its hit (beams no longer than that
    walk nowhere); ``into`` and ``reach`` get which beams walk and how far. ``clear``: as
    ``walk_beams`` takes it. Returns the new count."""
    unknown_walks(ref, ranges, expected, directions, found, short, into, reach)
    return walk_beams(ref, enclosed, clear, sensor, hits, reach, select=into, want=True,
                      drop_last=True, cap=cap, kind=WALK_OPEN_UNKNOWN, marks=marks, out=out,
                      n=n, skip=NO_SKIPS)


@njit(cache=True)
def unknown_walks(ref, ranges, expected, directions, found, short, into, reach):
    """Which beams ``flag_unknown_seen_through`` walks (``into``) and how far (``reach``)."""
    for i in range(ranges.shape[0]):
        r = ranges[i]
        into[i] = False
        reach[i] = 0.0
        if not (r > short) or not found[i] or not ends_in_unknown(ref, expected, directions, i):
            continue    # a NaN range (an invalid beam) is not above short either
        into[i] = True
        reach[i] = 1.0 - short / r


@njit(cache=True)
def flag_listed_unchanged(cells, marks, out, n):
    """Unchanged flags for ``cells``, appended to ``out`` from position n unless a cell has one
    already (``marks``). Returns the new count."""
    for k in range(cells.shape[0]):
        if test_and_set(marks, cells[k]):
            out[n] = cells[k]
            n += 1
    return n


@njit(cache=True)
def hit_slot(directory, width, idx):
    """(tile, offset) of flat cell ``idx`` in the hit buffers' pool (``hit_tiles.HitTiles``);
    tile -1 where no tile was made (every buffer there is 0)."""
    row = idx // width
    col = idx - row * width
    tile = directory[row >> HIT_TILE_SHIFT, col >> HIT_TILE_SHIFT]
    return tile, ((row & HIT_TILE_MASK) << HIT_TILE_SHIFT) | (col & HIT_TILE_MASK)


@njit(cache=True)
def missing_hit_tiles(directory, width, cells, out):
    """The tiles (flat index into ``directory``) of ``cells`` that have none yet, into
    ``out``, repeats and all. Returns the count."""
    n = 0
    for k in range(cells.shape[0]):
        row = cells[k] // width
        col = cells[k] - row * width
        tr, tc = row >> HIT_TILE_SHIFT, col >> HIT_TILE_SHIFT
        if directory[tr, tc] < 0:
            out[n] = tr * directory.shape[1] + tc
            n += 1
    return n


@njit(cache=True)
def make_hit_tiles(directory, rows, count, tiles):
    """``HitTiles.make`` while the pool (``rows`` tiles) has room for all of ``tiles`` (flat
    indices into ``directory``, repeats allowed, each missing): the same tiles made in the same
    order, ``count[0]`` the tiles in use. Returns 0, or the count of ``tiles`` when there is no
    room and nothing was made."""
    order = np.sort(tiles)
    n_new = 0
    for k in range(order.shape[0]):
        n_new += k == 0 or order[k] != order[k - 1]
    if count[0] + n_new > rows:
        return tiles.shape[0]
    flat = directory.reshape(-1)
    for k in range(order.shape[0]):
        if k == 0 or order[k] != order[k - 1]:
            flat[order[k]] = count[0]
            count[0] += 1
    return 0


@njit(cache=True)
def push_hits(directory, pool, width, ref_flat, enclosed, hit_cells, changed, mask, threshold,
              few, hit_marks, drawn):
    """The hit buffers of open unknown cells, ``hit = ((hit << 1) | flag) & mask`` (in the
    tiles of ``directory`` and ``pool``; the hit cells' tiles exist): 1 for each cell hit
    this scan, 0 for each seen through (its changed flag); then the ``drawn`` bit: hits in at
    least ``threshold`` of the last observations, or (``few`` > 0) only hits since the first,
    at least ``few`` of them. Clears ``hit_marks``. Returns the change of the number of drawn
    cells."""
    delta = 0
    n_changed = changed.shape[0]
    for k in range(n_changed + hit_cells.shape[0]):
        if k < n_changed:
            idx, flag = changed[k], 0
            tile, off = hit_slot(directory, width, idx)
            if tile < 0 or pool[tile, off] == 0 or not is_open_unknown(ref_flat, enclosed, idx):
                continue            # a 0 into an empty buffer: no change
        else:
            idx, flag = hit_cells[k - n_changed], 1
            tile, off = hit_slot(directory, width, idx)
            hit_marks[idx >> 3] = 0
        h = ((pool[tile, off] << 1) | flag) & mask
        pool[tile, off] = h
        now = is_drawn(h, mask, threshold, few)
        if now != (bit_get(drawn, idx) == 1):
            drawn[idx >> 3] = drawn[idx >> 3] ^ (1 << (idx & 7))
            delta += 1 if now else -1
    return delta


@njit(cache=True)
def is_drawn(h, mask, threshold, few):
    """A hit buffer that draws its cell: ``threshold`` hits among the last observations, or
    with ``few`` > 0 nothing but hits (the low bits all set), at least ``few``."""
    n = popcount16(h & mask)
    return n >= threshold or (few > 0 and n >= few and (h & (h + 1)) == 0)


@njit(cache=True)
def decide_drawn(directory, pool, height, width, ref_flat, enclosed, mask, threshold, few,
                 drawn):
    """The ``drawn`` bits over every tile of hit buffers (on loading a saved state). Returns
    the count."""
    total = 0
    side = 1 << HIT_TILE_SHIFT
    for tr in range(directory.shape[0]):
        for tc in range(directory.shape[1]):
            tile = directory[tr, tc]
            if tile < 0:
                continue
            for off in range(side * side):
                row = (tr << HIT_TILE_SHIFT) + (off >> HIT_TILE_SHIFT)
                col = (tc << HIT_TILE_SHIFT) + (off & HIT_TILE_MASK)
                h = pool[tile, off]
                if h == 0 or row >= height or col >= width:
                    continue
                idx = row * width + col
                if is_drawn(h, mask, threshold, few) and is_open_unknown(ref_flat, enclosed, idx):
                    drawn[idx >> 3] = drawn[idx >> 3] | (1 << (idx & 7))
                    total += 1
    return total


@njit(cache=True)
def apply_drawn(drawn, out):
    """The drawn cells become occupied in ``out`` (flat)."""
    for b in range(drawn.shape[0]):
        if drawn[b] == 0:
            continue
        for idx in range(b * 8, min(b * 8 + 8, out.shape[0])):
            if bit_get(drawn, idx):
                out[idx] = OCCUPIED


# --- all the walks of a scan, one per beam ---------------------------------------------------
# A beam may walk twice: a detected change to free the removed obstacle, or an agreeing beam to
# confirm free space, and again into the unknown space it sees through. One traversal to the
# further end flags for both: the removed-obstacle walk's kind (occupied or unknown) holds the
# open unknown; an agreeing beam's cells are free (an unchanged flag) or open unknown (a changed
# one), never both.


@njit(cache=True, inline="always")
def _walk_count(gx0, gy0, hit, reach, drop_last, cap, height, width):
    """The cells ``walk_beams`` walks for one beam: to ``reach`` of the way to ``hit``."""
    tx = gx0 + reach * (hit[0] - gx0)
    ty = gy0 + reach * (hit[1] - gy0)
    start = segment_start(gx0, gy0, tx, ty, height, width)
    n_x, n_y = start[2], start[3]
    count = min(n_x + n_y + 1, cap) if n_x >= 0 else 0
    if count > 0 and drop_last and 0.0 <= tx < width and 0.0 <= ty < height:
        count -= 1
    return count


@njit(cache=True)
def walk_scan(ref, enclosed, clear, sensor, hits, removed_select, removed_reach, verdict,
              free_reach, skips, into, unknown_reach, entered, cap, ch_marks, un_marks, changed,
              n_ch, unchanged, n_un):
    """The removed-obstacle walks (``removed_select`` CHANGE), the free walks (``verdict``
    UNCHANGED) and the walks into unknown space (``into``) of ``walk_beams``, each beam walked
    once to the furthest of its ends: changed flags into ``changed`` after n_ch (marks
    ``ch_marks``), unchanged ones into ``unchanged`` after n_un (``un_marks``). The flags are
    those of the walks one after the other, up to the order of the lists and to the cells
    where a segment passes within about 1e-12 of a corner (the shorter walk's cells are taken
    as the first ones of the longer). ``skips``: ``free_walk_skips``, used by the beams that
    walk free space only. ``entered`` (an empty array: none): per beam, where its expected
    ray met the first cell of M that is not free, or ended (``expected``); a beam whose walks
    flag no free cell (a removed-obstacle walk, a walk into unknown space, or both) starts
    ``ENTRY_MARGIN`` short of it, as every cell its ray crossed before lies free. Returns
    (n_ch, n_un)."""
    height, width = ref.shape
    flat = ref.reshape(-1)
    gx0, gy0 = sensor[0], sensor[1]
    for i in range(hits.shape[0]):
        a = removed_select[i] == CHANGE and removed_reach[i] > 0.0
        f = verdict[i] == UNCHANGED and free_reach[i] > 0.0
        u = into[i] and unknown_reach[i] > 0.0
        if not (a or f or u):
            continue
        reach = removed_reach[i] if a else (free_reach[i] if f else unknown_reach[i])
        first = second = -1     # a single walk: its own cells, counted where it is walked
        if u and (a or f):
            first = _walk_count(gx0, gy0, hits[i], reach, not f, cap, height, width)
            second = _walk_count(gx0, gy0, hits[i], unknown_reach[i], True, cap, height,
                                 width)
            if second > first:
                reach = unknown_reach[i]
        late = skips[i] if f and not u else 0.0
        if not f and entered.shape[0] > 0:
            late = max(math.sqrt((entered[i, 0] - gx0) ** 2 + (entered[i, 1] - gy0) ** 2)
                       - ENTRY_MARGIN, 0.0)
        n_ch, n_un = _walk_phases(flat, enclosed, clear, width, height, gx0, gy0, hits[i],
                                  reach, a, f, u, first, second, cap, late, ch_marks, un_marks,
                                  changed, n_ch, unchanged, n_un)
    return n_ch, n_un


@njit(cache=True, inline="always")
def _walk_phases(flat, enclosed, clear, width, height, gx0, gy0, hit, reach, a, f, u, first,
                 second, cap, skip, ch_marks, un_marks, changed, n_ch, unchanged, n_un):
    """One beam of ``walk_scan``: the segment to ``reach`` of the way to ``hit``; the first
    ``first`` cells flagged as its removed-obstacle (``a``) or free (``f``) walk flags them,
    the first ``second`` as its walk into unknown space (``u``) does (-1 for a beam with one
    walk: that walk's own cells); from ``skip`` grid units from the sensor (0: from it)."""
    tx = gx0 + reach * (hit[0] - gx0)
    ty = gy0 + reach * (hit[1] - gy0)
    cx, cy, n_x, n_y, step_x, step_y, t_delta_x, t_delta_y, t_max_x, t_max_y = \
        segment_start(gx0, gy0, tx, ty, height, width)
    if first < 0:       # one walk (the free walk keeps its last cell)
        own = min(n_x + n_y + 1, cap) if n_x >= 0 else 0
        if own > 0 and not f and 0.0 <= tx < width and 0.0 <= ty < height:
            own -= 1
        first, second = (own, 0) if a or f else (0, own)
    # a late start only for a walk that ``cap`` does not cut short (it counts from the start)
    cx, cy, n_x, n_y, t_max_x, t_max_y, done = _walk_start(
        clear, not f, skip if 0 <= n_x and n_x + n_y + 1 <= cap else 0.0, gx0, gy0, tx, ty,
        cx, cy, n_x, n_y, step_x, step_y, t_delta_x, t_delta_y, t_max_x, t_max_y)
    idx = cy * width + cx
    row_step = step_y * width
    both = min(first, second) if (a or f) and u else 0
    rest = max(first, second) if u else first
    later = WALK_OPEN_UNKNOWN if second > first or not (a or f) else \
        (WALK_BLOCKED if a else WALK_FREE)
    # the common cells: an agreeing beam's two kinds, or the removed walk's (which hold the
    # open unknown); then the longer walk's alone
    if f and both > done:
        n_ch, n_un, idx, n_x, n_y, t_max_x, t_max_y = _walk_free_and_unknown(
            flat, enclosed, idx, n_x, n_y, both - done, step_x, row_step, t_delta_x,
            t_delta_y, t_max_x, t_max_y, ch_marks, un_marks, changed, n_ch, unchanged, n_un)
        done = both
    if later == WALK_FREE:
        n_un = _walk_cells(flat, enclosed, WALK_FREE, idx, n_x, n_y, rest - done, step_x,
                           row_step, t_delta_x, t_delta_y, t_max_x, t_max_y, un_marks,
                           unchanged, n_un)
    elif a and later == WALK_OPEN_UNKNOWN and first > done:
        n_ch, idx, n_x, n_y, t_max_x, t_max_y = _walk_cells_on(
            flat, enclosed, WALK_BLOCKED, idx, n_x, n_y, first - done, step_x, row_step,
            t_delta_x, t_delta_y, t_max_x, t_max_y, ch_marks, changed, n_ch)
        n_ch = _walk_cells(flat, enclosed, WALK_OPEN_UNKNOWN, idx, n_x, n_y, rest - first,
                           step_x, row_step, t_delta_x, t_delta_y, t_max_x, t_max_y, ch_marks,
                           changed, n_ch)
    elif later == WALK_OPEN_UNKNOWN:    # each kind a loop of its own, with no test of it
        n_ch = _walk_cells(flat, enclosed, WALK_OPEN_UNKNOWN, idx, n_x, n_y, rest - done,
                           step_x, row_step, t_delta_x, t_delta_y, t_max_x, t_max_y, ch_marks,
                           changed, n_ch)
    else:
        n_ch = _walk_cells(flat, enclosed, WALK_BLOCKED, idx, n_x, n_y, rest - done, step_x,
                           row_step, t_delta_x, t_delta_y, t_max_x, t_max_y, ch_marks,
                           changed, n_ch)
    return n_ch, n_un


@njit(cache=True, inline="always")
def _walk_cells_on(flat, enclosed, kind, idx, n_x, n_y, count, step_x, row_step, t_delta_x,
                   t_delta_y, t_max_x, t_max_y, marks, out, n):
    """``_walk_cells``, returning where the walk stands after it: (n, idx, n_x, n_y, t_max_x,
    t_max_y)."""
    for _ in range(count):
        b = idx >> 3
        bit = np.uint8(1 << (idx & 7))
        old = marks[b]
        if kind == WALK_FREE:
            # most free cells are marked already (settled_marks): a branch that is rarely
            # taken costs less than a store at every cell, and M is read only past it
            if (old & bit) == 0 and flat[idx] == FREE:
                marks[b] = old | bit
                out[n] = idx
                n += 1
        else:
            v = flat[idx]
            if kind == WALK_BLOCKED:
                wanted = v != FREE
            else:
                wanted = v != FREE and v != OCCUPIED and (enclosed[b] & bit) == 0
            take = wanted & ((old & bit) == 0)
            marks[b] = old | (bit if take else np.uint8(0))
            out[n] = idx
            n += take
        idx, n_x, n_y, t_max_x, t_max_y = _next_cell(idx, n_x, n_y, t_max_x, t_max_y, step_x,
                                                     row_step, t_delta_x, t_delta_y)
    return n, idx, n_x, n_y, t_max_x, t_max_y


@njit(cache=True, inline="always")
def _walk_free_and_unknown(flat, enclosed, idx, n_x, n_y, count, step_x, row_step, t_delta_x,
                           t_delta_y, t_max_x, t_max_y, ch_marks, un_marks, changed, n_ch,
                           unchanged, n_un):
    """``count`` cells of an agreeing beam's walk that also looks into unknown space: a free
    cell gets an unchanged flag, an open unknown one a changed flag, each once."""
    for _ in range(count):
        v = flat[idx]
        b = idx >> 3
        bit = np.uint8(1 << (idx & 7))
        if v == FREE:
            if (un_marks[b] & bit) == 0:
                un_marks[b] |= bit
                unchanged[n_un] = idx
                n_un += 1
        elif v != OCCUPIED and (enclosed[b] & bit) == 0 and (ch_marks[b] & bit) == 0:
            ch_marks[b] |= bit
            changed[n_ch] = idx
            n_ch += 1
        idx, n_x, n_y, t_max_x, t_max_y = _next_cell(idx, n_x, n_y, t_max_x, t_max_y, step_x,
                                                     row_step, t_delta_x, t_delta_y)
    return n_ch, n_un, idx, n_x, n_y, t_max_x, t_max_y


# --- steps 2 and 3 in one call ----------------------------------------------------------------
@njit(cache=True)
def flag_scan(ref, enclosed, clear, sensor, hits, ranges, verdict, removed_select,
              removed_reach, tol, free_reach, expected, directions, found, guard,
              unknown_guard, grow, short, gaps, margin, confirm, cap, increment, wrap, skips,
              ch_marks, un_marks, hit_marks, protected, hits_unknown, into, unknown_reach,
              scratch, changed, unchanged):
    """The flags of a scan past the lost check, as ``MapUpdater``'s steps (``updater.steps``)
    give them one after the other: the seen-surface guard (radius ``guard``, 0: none; around the
    hits that ``guard_needed`` finds near a walk the guard changes, into the scratch
    ``scratch``, a bool per beam, which then holds the new obstacles' beams), the unknown cells
    hit (``grow``), the removed-obstacle walks, the new-obstacle flags, the walks into unknown
    space, the guard released, ``fill_gaps`` (clearance ``gaps``, 0: off; the free walks then
    reach to ``margin`` short of the hit where that is further), the free walks, the unchanged
    flags of occupied cells, the hits that confirm M's surfaces (``confirm``), and the unknown
    hits' marks released. One call instead of a dozen: each call from Python has a fixed cost.
    The walks are ``walk_scan``'s, one per beam, before the new-obstacle flags (a free hit cell:
    no walk flags one) and the guard's release (which the free walks, whose marks are their own,
    do not see), with ``walk_beams``' shortcuts: ``clear`` (``clear_blocks`` of ``ref``) and the
    free walks' ``free_walk_skips`` (``increment``, ``wrap``), written to the scratch ``skips``.
    Returns (changed flags, new-obstacle flags, fill_gaps flags, unchanged flags, unknown cells
    hit)."""
    if grow:
        unknown_walks(ref, ranges, expected, directions, found, short, into, unknown_reach)
    else:
        into[:] = False
    n_guarded = 0
    if guard > 0.0:
        guard_needed(sensor, hits, verdict, removed_select, removed_reach, into,
                     unknown_reach, guard, increment, scratch)
        n_guarded = mark_seen_surfaces(ref, enclosed, hits, verdict, guard, unknown_guard,
                                       ch_marks, protected, scratch)
    n_hits = list_unknown_hits(ref, enclosed, hits, verdict, hit_marks, ch_marks,
                               hits_unknown) if grow else 0
    if gaps > 0:
        for i in range(ranges.shape[0]):
            if margin > 0.0 and margin < ranges[i]:
                free_reach[i] = np.maximum(free_reach[i], 1.0 - margin / ranges[i])
    free_walk_skips(sensor, hits, free_reach, verdict, UNCHANGED, increment, wrap, cap, skips)
    unmark_changing(ref, hits, tol, verdict, gaps, ch_marks, un_marks, scratch)
    n, n_un = walk_scan(ref, enclosed, clear, sensor, hits, removed_select, removed_reach,
                        verdict, free_reach, skips, into, unknown_reach, expected, cap,
                        ch_marks, un_marks, changed, 0, unchanged, 0)
    n_ch = flag_new_obstacles(ref, hits, tol, verdict, ch_marks, changed, n, scratch)
    n_new = n_ch - n
    clear_bits(ch_marks, protected, n_guarded)
    n_gaps = 0
    if gaps > 0:
        n_gaps = flag_gaps(ref, hits, verdict, gaps, ch_marks, changed, n_ch) - n_ch
        n_ch += n_gaps
    n_un = flag_occupied_unchanged(ref, hits, verdict, un_marks, unchanged, n_un)
    if confirm:
        n_un = flag_hit_surfaces(ref, hits, verdict, un_marks, unchanged, n_un)
    if grow:
        clear_bits(ch_marks, hits_unknown, n_hits)
        n_un = flag_listed_unchanged(hits_unknown[:n_hits], un_marks, unchanged, n_un)
    return n_ch, n_new, n_gaps, n_un, n_hits


@njit(cache=True)
def flag_push_decide(ref, enclosed, clear, sensor, hits, ranges, verdict, removed_select,
                     removed_reach, tol, free_reach, expected, directions, found, guard,
                     unknown_guard, grow, short, gaps, margin, confirm, cap, increment, wrap,
                     skips, ch_marks, un_marks, hit_marks, protected, hits_unknown, into,
                     unknown_reach, scratch, changed, unchanged, hist, seen, decided, mask,
                     threshold, few, support, moved, shift, full, directory, pool, used, drawn,
                     missing):
    """``flag_scan``, then ``push_and_decide`` if ``moved`` has room for the scan's flags, then
    (``grow``) ``push_hits`` once every unknown cell hit has its tile (``missing_hit_tiles``,
    into ``missing``; ``make_hit_tiles`` while the pool has room, ``used`` the tiles in use):
    one call from Python instead of four. Returns (changed flags,
    new-obstacle flags, fill_gaps flags, unchanged flags, unknown cells hit, the change of the
    number of changed cells, that of the drawn cells, the tiles missing: -1 when ``moved``
    had no room, and neither push was made)."""
    n_ch, n_new, n_gaps, n_un, n_hits = flag_scan(
        ref, enclosed, clear, sensor, hits, ranges, verdict, removed_select, removed_reach,
        tol, free_reach, expected, directions, found, guard, unknown_guard, grow, short, gaps,
        margin, confirm, cap, increment, wrap, skips, ch_marks, un_marks, hit_marks,
        protected, hits_unknown, into, unknown_reach, scratch, changed, unchanged)
    if n_ch + n_un > moved.shape[0]:
        return n_ch, n_new, n_gaps, n_un, n_hits, 0, 0, -1
    width = ref.shape[1]
    flat = ref.reshape(-1)
    d_changed = push_and_decide(hist, seen, flat, decided, changed[:n_ch], unchanged[:n_un],
                                mask, threshold, few, support, width, ch_marks, un_marks, moved,
                                shift, full)
    n_missing = missing_hit_tiles(directory, width, hits_unknown[:n_hits], missing) if grow \
        else 0
    if n_missing > 0:
        n_missing = make_hit_tiles(directory, pool.shape[0], used, missing[:n_missing])
    d_drawn = 0
    if grow and n_missing == 0:
        d_drawn = push_hits(directory, pool, width, flat, enclosed, hits_unknown[:n_hits],
                            changed[:n_ch], mask, threshold, few, hit_marks, drawn)
    return n_ch, n_new, n_gaps, n_un, n_hits, d_changed, d_drawn, n_missing


# What ``process_scan`` returns when the flag lists lack room for a scan's flags
NEEDS_ROOM = -2


@njit(cache=True)
def process_scan(ranges, r_lo, r_hi, sensor, angle_min, step, increment, ratio, res, dist,
                 floats, bits, verdicts, points, rays, out_found, ref, clear, max_len,
                 half_window, wrap, min_run, n_skip, min_width, lost_fraction, walk_skipped,
                 radius, unknown_guard, grow, short, gaps, margin, confirm_hits, cap, even,
                 ch_marks, un_marks, hit_marks, protected, hits_unknown, changed, unchanged,
                 hist, seen, decided, mask, threshold, few, support, moved, shift, full,
                 directory, pool, used, drawn, missing, enclosed):
    """A scan's whole way through the updater past the gate, in one call from Python (a call
    costs a few µs, which a scan of 180 beams feels): ``prepare_beams`` and ``classify_scan``
    (step 1), the lost check (``scan_is_lost``), then
    ``flag_push_decide`` for a scan that is not lost, with the guard (``radius``) and the
    hit surfaces' flags (``confirm_hits``) only when changes were kept, or (the guard) the
    scan grows into the unknown. The per-beam arrays come as rows of ``floats``, ``bits``,
    ``verdicts``, ``points`` and ``rays`` (``_beam_rows``); ``walk_skipped``: the skipped
    beams' removed-obstacle walks run. The measured beams' own virtual beams are every
    ``ratio``-th. ``hist`` and ``seen`` are the map's shape. Returns (valid beams, detected
    changes, changes kept by the run filter, the bound on the scan's flags, then
    ``flag_push_decide``'s eight results); the fifth is ``NEEDS_ROOM`` when ``changed`` and
    ``unchanged`` lack room for the bound (and nothing was flagged), -1 for a lost scan."""
    out_r, out_pairing, out_tol, out_skip, out_reach, out_free_reach, unknown_reach, skips, \
        out_valid, out_change, out_keep, into, scratch, out_verdict, out_select, out_hits, \
        out_measured, out_virtual, out_expected = _beam_rows(floats, bits, verdicts, points, rays)
    n_valid, bound = prepare_beams(ranges, r_lo, r_hi, sensor, angle_min, step, increment, ratio,
                                   res, dist, out_r, out_valid, out_virtual, out_measured,
                                   out_hits, out_pairing, out_tol, out_skip, out_reach,
                                   out_free_reach)
    raw, kept = classify_scan(ref, clear, sensor, out_virtual, max_len, out_hits, out_valid,
                              out_pairing, half_window, wrap, min_run, n_skip, out_expected,
                              out_found, out_change, out_keep, out_verdict, min_width)
    n = ranges.shape[0]
    bound = min(bound, ref.size) + n    # and room for an unchanged flag at each hit cell
    head = (np.int64(n_valid), np.int64(raw), np.int64(kept), np.int64(bound))
    if bound > changed.shape[0] or bound > unchanged.shape[0]:
        return head + (NEEDS_ROOM, 0, 0, 0, 0, 0, 0, 0)
    own = slice(0, n * ratio, ratio)
    expected, direction, found = out_expected[own], out_virtual[own], out_found[own]
    if scan_is_lost(ref, expected, direction, found, out_r, out_change, n_valid, raw,
                    lost_fraction):
        return head + (-1, 0, 0, 0, 0, 0, 0, 0)
    select = out_verdict
    if walk_skipped:
        for i in range(n):
            out_select[i] = CHANGE if out_verdict[i] == SKIPPED else out_verdict[i]
        select = out_select
    guard = radius if radius > 0.0 and (kept > 0 or grow) else 0.0
    confirm = confirm_hits and kept > 0     # (a call this long takes no expression inside)
    spacing, flat_hist, flat_seen = abs(increment), hist.reshape(-1), seen.reshape(-1)
    return head + flag_push_decide(
        ref, enclosed, clear, sensor, out_hits, out_r, out_verdict, select, out_reach, out_tol,
        out_free_reach, expected, direction, found, guard, unknown_guard, grow, short, gaps,
        margin, confirm, cap, spacing, even, skips, ch_marks, un_marks, hit_marks, protected,
        hits_unknown, into, unknown_reach, scratch, changed, unchanged, flat_hist, flat_seen,
        decided, mask, threshold, few, support, moved, shift, full, directory, pool, used, drawn,
        missing)


@njit(cache=True, inline="always")
def _beam_rows(floats, bits, verdicts, points, rays):
    """``process_scan``'s per-beam arrays, by name: the rows in the order of ``Workspace``'s
    ``FLOATS``, ``BITS``, ``VERDICTS``, ``POINTS`` and ``RAYS`` (``updater.steps``)."""
    return (floats[0], floats[1], floats[2], floats[3], floats[4], floats[5], floats[6],
            floats[7], bits[0], bits[1], bits[2], bits[3], bits[4], verdicts[0], verdicts[1],
            points[0], points[1], rays[0], rays[1])


@njit(cache=True)
def push_and_decide(hist, seen, ref, decided, changed, unchanged, mask, threshold, few,
                    support, width, ch_marks, un_marks, moved, shift=0, full=NEVER_SETTLED):
    """``push_flags`` then ``decide`` in one call, the changed-flag marks kept between scans on
    the cells whose buffers are full of changes (``push_flags``' ``settle``) and serving the
    decision as its stamps: those cells stay changed whatever their neighbours do, so the
    decision may take them as done. Returns the change of the number of changed cells."""
    # the changed flags' entries first, so that the decision knows which way each crossed
    n_up = push_flags(hist, seen, ref, changed, unchanged[:0], mask, threshold, few, ch_marks,
                      un_marks, moved, shift, full, decided, True)
    n_moved = n_up + push_flags(hist, seen, ref, changed[:0], unchanged, mask, threshold, few,
                                ch_marks, un_marks, moved[n_up:], shift, full, decided, True)
    return decide(hist, seen, ref, decided, moved[:n_moved], width, mask, threshold, few,
                  support, ch_marks, shift, n_up, True)


# --- buffers and decision ---------------------------------------------------------------------
# Shortcuts of the push and the decision, each leaving the buffers and the decided bits as
# they were without it (docs/algorithm.md):
# - ``decided``: a cell whose flag agrees with its decided bit, and whose count did not cross
#   the threshold, is not re-decided. A changed flag does not lower n_c and keeps a unanimous
#   record unanimous (or lifts it to T); an unchanged one does not raise n_c and breaks
#   unanimity: the rule cannot turn such a cell. Only a crossing changes its neighbours'.
# - ``n_up``: around a crossing, a changed flag only raises n_c and ends a surface's
#   confirmation (``confirmed``), an unchanged one the opposite, and the rule grows with the
#   neighbours' n_c and shrinks with their confirmation: so around a changed flag's crossing
#   only the cells not yet changed can turn, around an unchanged flag's only the changed ones.
# - ``settle``: the changed-flag marks stay set between scans on the cells whose buffers are
#   full of changes (set when a changed flag fills one without a crossing, cleared when an
#   unchanged flag enters one). A walk makes no changed flag there; it would change nothing
#   but a count past N_b, which no rule reads (they read counts against T <= N_b, or
#   min(count, N_b)). Such a cell is changed whatever its neighbours do, so the decision takes
#   these marks as its stamps (``keep_full``: done) and leaves them.
@njit(cache=True)
def push_flags(hist, seen, ref, changed, unchanged, mask, threshold, few, ch_marks, un_marks,
               out_moved, shift=0, full=NEVER_SETTLED, decided=None, settle=False):
    """Shift the scan's flags into the buffers, changed flags first:
    ``hist = ((hist << 1) | flag) & mask`` in the buffer's low bits, count each flag
    (``flag_count``: in ``seen``, or with ``shift`` > 0 above the flags; an empty ``seen``
    and ``shift`` 0 count nothing, and then ``few`` must be 0) and clear the scan's marks.
    ``out_moved`` gets each cell whose count n_c changed (or, with the rule for few
    observations, ``few`` > 0, whose observations are still below the threshold), as ``idx``,
    or as ``-1 - idx`` when n_c crossed the threshold (its neighbours' support changed too).
    With ``full`` (``settled``'s bound), the unchanged-flag marks are kept between scans on
    the free cells whose buffers are settled, and only on those (``settled_marks``): a free
    walk makes no flag that would change nothing. ``decided``, ``settle``: the shortcuts
    above. Returns the count written."""
    n = 0
    n_changed = changed.shape[0]
    keep = full != NEVER_SETTLED
    # the count's lowest bit (0: an array of its own), written out: a call slowed the loop
    unit = np.int64(1) << shift if shift > 0 else 0
    counting = seen.shape[0] > 0
    for k in range(n_changed + unchanged.shape[0]):
        idx, flag = (changed[k], 1) if k < n_changed else (unchanged[k - n_changed], 0)
        if flag == 0 and not keep:
            un_marks[idx >> 3] = 0
        h = np.int64(hist[idx])
        old = h & mask
        if flag == 1 or (settle and old == mask):   # the bit alone: the others may be settled
            set_bit(ch_marks, idx, False)
        free = ref[idx] == FREE
        watched = few > 0 and ref[idx] == OCCUPIED
        was = watched and confirmed(hist, seen, ref, idx, mask, shift)
        if unit > 0:
            if h + unit <= 0xFFFF:      # past it, the count (the top field) would wrap
                h += unit
                hist[idx] = np.uint16(h)
        elif counting and seen[idx] < 255:
            seen[idx] += 1
        if old == 0 and flag == 0 and not watched:
            if keep:
                set_bit(un_marks, idx, free and h >= full)
            continue            # an unchanged flag into an all-unchanged buffer: no change
        new = ((old << 1) | flag) & mask
        h = (h & ~mask) | new
        hist[idx] = np.uint16(h)
        if keep:
            set_bit(un_marks, idx, free and settled(h, mask, full))
        p_old, p_new = popcount16(old), popcount16(new)
        crossed = (p_old >= threshold) != (p_new >= threshold)
        if watched and was != confirmed(hist, seen, ref, idx, mask, shift):
            crossed = True      # its neighbours' unanimous rule changed too
        if settle and new == mask and flag == 1 and not crossed:
            set_bit(ch_marks, idx, True)
        if crossed:
            out_moved[n] = -1 - idx
            n += 1
        elif decided is not None and ((decided[idx >> 3] >> (idx & 7)) & 1) == flag:
            continue            # the decision cannot turn (see above)
        elif p_old != p_new or (few > 0 and flag_count(hist, seen, idx, shift) <= threshold):
            out_moved[n] = idx
            n += 1
    return n


@njit(cache=True, inline="always")
def settled(h, mask, full):
    """Whether an unchanged flag would change nothing in a buffer ``h``: all its flags
    (``mask``) are unchanged, and its flag count is past every bound a rule reads it against
    (``h`` >= ``full``: that bound shifted to where the count starts; 0 when no count is
    kept). ``push_flags`` passes over such a flag."""
    return (h & mask) == 0 and h >= full


@njit(cache=True)
def settled_marks(ref, hist, mask, full, out):
    """The unchanged-flag marks between scans (``push_flags`` with ``full``): the bits of the
    free cells of M (``ref``, flat) whose buffers are ``settled``."""
    out[:] = 0
    if full == NEVER_SETTLED:
        return
    for i in range(ref.shape[0]):
        if ref[i] == FREE and settled(np.int64(hist[i]), mask, full):
            out[i >> 3] |= np.uint8(1 << (i & 7))


@njit(cache=True, inline="always")
def confirmed(hist, seen, ref, idx, mask, shift=0):
    """An occupied cell of M whose recent flags are not all changed: a surface the scans still
    see. The unanimous rule frees no occupied cell next to one. (Why a count must reach N_b
    before it saturates: the last min(count, N_b) flags are the ones to look at.)"""
    if ref[idx] != OCCUPIED:
        return False
    seen_n = flag_count(hist, seen, idx, shift)
    if seen_n == 0:
        return False
    window = popcount16(mask)
    return popcount16(hist[idx] & mask) < min(seen_n, window)


@njit(cache=True, inline="always")
def same_state(a, b, support):
    """Whether two cells of M count as of the same state for the neighbour support: the
    paper's two states (free / occupied-or-unknown), or, with ``support`` 2, the same value,
    so that unknown cells seen through lend an occupied one no support."""
    if support == 2:
        return a == b
    return (a != FREE) == (b != FREE)


@njit(cache=True)
def decide_cell(hist, seen, ref, decided, idx, width, mask, threshold, few, support, shift=0):
    """Apply the decision rule to cell ``idx`` (flat arrays) and update its decided bit: changed
    when n_c >= T; or, with ``few`` > 0, when the cell was observed fewer than T times, at least
    ``few`` times, and every flag it got says changed (an occupied cell of M only if no occupied
    8-neighbour is ``confirmed``: a wall grazed by a few beams keeps its cells); or, with
    ``support``, when n_c plus its 8-neighbours of the same state in ``ref``
    (``same_state``) with n >= T reaches T. Returns +1, -1 or 0, the change of
    the number of changed cells."""
    n = popcount16(hist[idx] & mask)
    changed = n >= threshold
    if not changed and few > 0:
        seen_n = flag_count(hist, seen, idx, shift)
        changed = n >= few and seen_n < threshold and n == seen_n
        if changed and ref[idx] == OCCUPIED:     # not a cell of a surface the scans still see
            height = ref.shape[0] // width
            row, col = idx // width, idx % width
            for rr in range(max(row - 1, 0), min(row + 2, height)):
                for cc in range(max(col - 1, 0), min(col + 2, width)):
                    j = rr * width + cc
                    if j != idx and confirmed(hist, seen, ref, j, mask, shift):
                        changed = False
    if not changed and support:
        height = ref.shape[0] // width
        row, col = idx // width, idx % width
        for rr in range(max(row - 1, 0), min(row + 2, height)):
            for cc in range(max(col - 1, 0), min(col + 2, width)):
                j = rr * width + cc
                if j != idx and same_state(ref[j], ref[idx], support) and \
                        popcount16(hist[j] & mask) >= threshold:
                    n += 1
        changed = n >= threshold
    if changed == (bit_get(decided, idx) == 1):
        return 0
    decided[idx >> 3] = decided[idx >> 3] ^ (1 << (idx & 7))
    return 1 if changed else -1


@njit(cache=True)
def decide(hist, seen, ref, decided, moved, width, mask, threshold, few, support, stamp=None,
           shift=0, n_up=-1, keep_full=False):
    """Re-decide every cell whose own inputs moved, and the 8-neighbours of those whose count
    crossed the threshold: no other cell's inputs changed. The rule reads only the buffers, so
    each cell is decided once however many entries name it: ``stamp`` (bits per cell, all
    clear, and cleared again before returning; a scratch plane when not given) tells which
    are done. The rule is ``decide_cell``'s, written out in the loop: a call taking the
    arrays, inlined or not, counts a reference to each of them per cell. ``n_up`` (-1: not
    known): the entries before it come from changed flags, the others from unchanged ones;
    ``keep_full``: ``stamp`` holds the changed-flag marks of ``settle`` (the shortcuts above
    ``push_flags``). Returns the change of the number of changed cells."""
    if stamp is None:
        stamp = np.zeros((ref.shape[0] + 7) // 8, np.uint8)
    height = ref.shape[0] // width
    window = popcount16(mask)
    delta = 0
    for k in range(moved.shape[0]):
        idx = moved[k] if moved[k] >= 0 else -1 - moved[k]
        lo, hi = neighbourhood(idx, width, ref.shape[0], (support or few > 0) and moved[k] < 0)
        # the decided bit that cannot turn around this entry (2: none)
        kept = 2 if n_up < 0 or moved[k] >= 0 else (1 if k < n_up else 0)
        for row_start in range(lo, hi + 1, width):
            for i in range(row_start, row_start + (hi - lo) % width + 1):
                if stamp[i >> 3] & (1 << (i & 7)) or ((decided[i >> 3] >> (i & 7)) & 1) == kept:
                    continue
                stamp[i >> 3] |= np.uint8(1 << (i & 7))
                n = popcount16(hist[i] & mask)
                changed = n >= threshold
                row, col = i // width, i % width
                r0, r1 = max(row - 1, 0), min(row + 2, height)
                c0, c1 = max(col - 1, 0), min(col + 2, width)
                if not changed and few > 0:
                    seen_n = flag_count(hist, seen, i, shift)
                    changed = n >= few and seen_n < threshold and n == seen_n
                    if changed and ref[i] == OCCUPIED:   # no neighbour of a seen surface
                        for rr in range(r0, r1):
                            for j in range(rr * width + c0, rr * width + c1):
                                if j != i and ref[j] == OCCUPIED:
                                    seen_j = flag_count(hist, seen, j, shift)
                                    if seen_j and popcount16(hist[j] & mask) < min(seen_j,
                                                                                   window):
                                        changed = False
                if not changed and support:
                    for rr in range(r0, r1):
                        for j in range(rr * width + c0, rr * width + c1):
                            if j != i and same_state(ref[j], ref[i], support) and \
                                    popcount16(hist[j] & mask) >= threshold:
                                n += 1
                    changed = n >= threshold
                if changed != (((decided[i >> 3] >> (i & 7)) & 1) == 1):
                    decided[i >> 3] ^= np.uint8(1 << (i & 7))
                    delta += 1 if changed else -1
    clear_neighbourhoods(moved, width, ref.shape[0], support or few > 0, stamp,
                         hist if keep_full else None, mask)
    return delta


@njit(cache=True)
def clear_neighbourhoods(moved, width, size, spread, stamp, hist=None, mask=0):
    """Clear the ``stamp`` bytes of the cells ``decide`` stamped for ``moved``; with ``hist``,
    the bits alone, set on the cells whose buffers (``mask``) are full of changes, cleared on
    the others (the changed-flag marks as ``push_flags``' ``settle`` keeps them)."""
    for k in range(moved.shape[0]):
        idx = moved[k] if moved[k] >= 0 else -1 - moved[k]
        lo, hi = neighbourhood(idx, width, size, spread and moved[k] < 0)
        for row_start in range(lo, hi + 1, width):
            row_end = row_start + (hi - lo) % width
            if hist is None:
                stamp[row_start >> 3] = 0
                stamp[row_end >> 3] = 0
                continue
            for i in range(row_start, row_end + 1):
                set_bit(stamp, i, (hist[i] & mask) == mask)


@njit(cache=True)
def neighbourhood(idx, width, size, spread):
    """(first, last) cell of the block of cell ``idx`` and, with ``spread``, its
    8-neighbours on the map: its rows run from first to last in steps of ``width``."""
    if not spread:
        return idx, idx
    row, col = idx // width, idx % width
    c0, c1 = max(col - 1, 0), min(col + 1, width - 1)
    r0, r1 = max(row - 1, 0), min(row + 1, size // width - 1)
    return r0 * width + c0, r1 * width + c1


@njit(cache=True)
def decide_all(hist, seen, ref, decided, width, mask, threshold, few, support, shift=0):
    """The decision rule over the whole map (on loading a saved state, and in tests)."""
    total = 0
    for idx in range(ref.shape[0]):
        total += decide_cell(hist, seen, ref, decided, idx, width, mask, threshold, few, support,
                             shift)
    return total


# --- output and last check --------------------------------------------------------------------
@njit(cache=True)
def apply_changes(ref, decided, enclosed, width, close, hist, out, mask=0xFFFF):
    """``out`` (a copy of ``ref``, flat) gets the changed cells flipped: free -> occupied,
    occupied or unknown -> free. With ``close``, the last check: each 8-neighbour of a cell
    that became free that lies in an enclosed unknown region of ``ref`` and is itself unchanged
    (so still unknown) becomes occupied, unless ``hist`` (flat buffers, or an empty array;
    the flags are its ``mask`` bits) holds a changed flag for it: a cell seen through, if not
    yet often enough to be freed, is left unknown rather than drawn. Returns the count of
    cells the last check closed."""
    height = ref.shape[0] // width
    closed = 0
    for b in range(decided.shape[0]):
        if decided[b] == 0:
            continue
        for idx in range(b * 8, min(b * 8 + 8, ref.shape[0])):
            if not bit_get(decided, idx):
                continue
            out[idx] = OCCUPIED if ref[idx] == FREE else FREE
            if not close or ref[idx] == FREE:
                continue
            row, col = idx // width, idx % width
            for rr in range(max(row - 1, 0), min(row + 2, height)):
                for cc in range(max(col - 1, 0), min(col + 2, width)):
                    j = rr * width + cc
                    if bit_get(enclosed, j) and not bit_get(decided, j) and out[j] != OCCUPIED \
                            and (hist.shape[0] == 0 or (hist[j] & mask) == 0):
                        out[j] = OCCUPIED
                        closed += 1
    return closed


@njit(cache=True)
def spread_freed(ref, decided, hist, seen, width, mask, shift, max_cells, spread, done, big):
    """A removed object freed as a whole: from each occupied cell of ``ref`` that the rule
    changed, across the 8-neighbours occupied in ``ref`` whose every recent flag says changed
    (one at least), marked in ``spread`` (bits, all clear) and spread on from; only within
    the 8-connected occupied structures of ``ref`` of at most ``max_cells`` cells none of
    which is ``confirmed`` (objects the scans no longer see anywhere, not walls). ``done``,
    ``big``: scratch bit planes, all clear. Returns the count marked."""
    size = ref.shape[0]
    height = size // width
    members = np.empty(max_cells + 9, np.int64)
    stack = np.empty(256, np.int64)
    marked = 0
    for b in range(decided.shape[0]):
        if decided[b] == 0:
            continue
        for idx in range(b * 8, min(b * 8 + 8, size)):
            if not bit_get(decided, idx) or ref[idx] != OCCUPIED or bit_get(done, idx) or \
                    bit_get(big, idx):
                continue
            n, seen_still = _flood_occupied(ref, hist, seen, width, height, mask, shift, idx,
                                            max_cells, done, members)
            if n > max_cells or seen_still:     # a wall, a large or a present structure
                for k in range(n):
                    j = members[k]
                    done[j >> 3] &= np.uint8(~(1 << (j & 7)) & 0xFF)
                    big[j >> 3] |= np.uint8(1 << (j & 7))
                continue
            top = 0
            for k in range(n):
                if bit_get(decided, members[k]):
                    stack, top = _push(stack, top, members[k])
            while top > 0:
                top -= 1
                stack, top, added = _spread_from(ref, decided, hist, seen, width, height, mask,
                                                 shift, stack[top], spread, stack, top)
                marked += added
    return marked


@njit(cache=True)
def keep_beside_standing(ref, bits, hist, seen, width, mask, shift, threshold, max_cells, out):
    """``out`` (a copy of ``bits``): the bits cleared of the occupied cells of ``ref`` (flat)
    beside something that stands (``_stands_beside``). What is freed next to such a cell is a
    sliver of a face a beam grazed, or a face a pose error wore, not an object that went: the
    cells of a removed object go together, and its interior is seen through with it. Then, to
    a fixed point, the cells freed on fewer than ``threshold`` flags (the unanimous rule's)
    beside one kept so in a structure that stands (8-connected occupied cells of ``ref``, one
    of which the scans still see, ``confirmed``, or more than ``max_cells`` of them): a face
    worn along a run of cells stands with its ends, while a removed object that no scan hits
    goes whole. Returns the count cleared."""
    size = ref.shape[0]
    height = size // width
    anchored = np.zeros_like(out)       # cells kept in a structure that stands
    checked = np.zeros_like(out)        # cells whose structure was looked at ...
    stands = np.zeros_like(out)         # ... and found standing
    done = np.zeros_like(out)
    members = np.empty(max_cells + 9, np.int64)
    cleared = 0
    for b in range(bits.shape[0]):
        if bits[b] == 0:
            continue
        for idx in range(b * 8, min(b * 8 + 8, size)):
            if bit_get(bits, idx) and ref[idx] == OCCUPIED and \
                    _stands_beside(ref, bits, hist, seen, width, mask, shift, idx):
                out[idx >> 3] &= np.uint8(~(1 << (idx & 7)) & 0xFF)
                cleared += 1
                if _structure_stands(ref, hist, seen, width, height, mask, shift, idx,
                                     max_cells, checked, stands, done, members):
                    anchored[idx >> 3] |= np.uint8(1 << (idx & 7))
    more = cleared > 0
    while more:
        more = False
        for b in range(out.shape[0]):
            if out[b] == 0:
                continue
            for idx in range(b * 8, min(b * 8 + 8, size)):
                if bit_get(out, idx) and ref[idx] == OCCUPIED and \
                        flag_count(hist, seen, idx, shift) < threshold and \
                        _beside_anchored(ref, anchored, width, height, idx):
                    out[idx >> 3] &= np.uint8(~(1 << (idx & 7)) & 0xFF)
                    anchored[idx >> 3] |= np.uint8(1 << (idx & 7))
                    cleared += 1
                    more = True
    return cleared


@njit(cache=True)
def _structure_stands(ref, hist, seen, width, height, mask, shift, idx, max_cells, checked,
                      stands, done, members):
    """Whether the structure of occupied cell ``idx`` stands (``keep_beside_standing``),
    flooded once: the answer is kept for the cells visited (``checked``, ``stands``)."""
    if bit_get(checked, idx):
        return bit_get(stands, idx) == 1
    n, seen_still = _flood_occupied(ref, hist, seen, width, height, mask, shift, idx,
                                    max_cells, done, members)
    up = seen_still or n > max_cells
    for k in range(min(n, members.shape[0])):
        j = members[k]
        done[j >> 3] &= np.uint8(~(1 << (j & 7)) & 0xFF)
        checked[j >> 3] |= np.uint8(1 << (j & 7))
        if up:
            stands[j >> 3] |= np.uint8(1 << (j & 7))
    return up


@njit(cache=True, inline="always")
def _beside_anchored(ref, anchored, width, height, idx):
    row, col = idx // width, idx % width
    for rr in range(max(row - 1, 0), min(row + 2, height)):
        for cc in range(max(col - 1, 0), min(col + 2, width)):
            j = rr * width + cc
            if j != idx and ref[j] == OCCUPIED and bit_get(anchored, j):
                return True
    return False


@njit(cache=True, inline="always")
def _stands_beside(ref, bits, hist, seen, width, mask, shift, idx):
    """Whether an 8-neighbour of cell ``idx`` stands: occupied in ``ref`` with its bit clear,
    or unknown in ``ref`` and never flagged (no beam has passed through it or ended in it)."""
    height = ref.shape[0] // width
    row, col = idx // width, idx % width
    for rr in range(max(row - 1, 0), min(row + 2, height)):
        for cc in range(max(col - 1, 0), min(col + 2, width)):
            j = rr * width + cc
            if j == idx:
                continue
            if ref[j] == OCCUPIED and not bit_get(bits, j):
                return True
            if ref[j] == UNKNOWN and hist[j] & mask == 0 and flag_count(hist, seen, j, shift) == 0:
                return True
    return False


@njit(cache=True)
def _flood_occupied(ref, hist, seen, width, height, mask, shift, start, max_cells, done,
                    members):
    """The 8-connected occupied cells of ``ref`` with ``start`` into ``members``, marked in
    ``done``; stops once more than ``max_cells`` are found, or one of them is ``confirmed``
    (a part of the structure the scans still see). Returns (how many, whether one is)."""
    members[0] = start
    done[start >> 3] |= np.uint8(1 << (start & 7))
    n, k = 1, 0
    while k < n:
        idx = members[k]
        k += 1
        if confirmed(hist, seen, ref, idx, mask, shift):
            return n, True
        row, col = idx // width, idx % width
        for rr in range(max(row - 1, 0), min(row + 2, height)):
            for cc in range(max(col - 1, 0), min(col + 2, width)):
                j = rr * width + cc
                if ref[j] == OCCUPIED and not bit_get(done, j):
                    done[j >> 3] |= np.uint8(1 << (j & 7))
                    members[n] = j
                    n += 1
        if n > max_cells:
            return n, False
    return n, False


@njit(cache=True)
def _spread_from(ref, decided, hist, seen, width, height, mask, shift, idx, spread, stack, top):
    """Mark and push the neighbours of ``idx`` the spread takes (``spread_freed``)."""
    window = popcount16(mask)
    added = 0
    row, col = idx // width, idx % width
    for rr in range(max(row - 1, 0), min(row + 2, height)):
        for cc in range(max(col - 1, 0), min(col + 2, width)):
            j = rr * width + cc
            if ref[j] != OCCUPIED or bit_get(decided, j) or bit_get(spread, j):
                continue
            seen_n = flag_count(hist, seen, j, shift)
            if seen_n == 0 or popcount16(hist[j] & mask) < min(seen_n, window):
                continue
            spread[j >> 3] |= np.uint8(1 << (j & 7))
            added += 1
            stack, top = _push(stack, top, j)
    return stack, top, added


@njit(cache=True, inline="always")
def _push(stack, top, idx):
    if top == stack.shape[0]:
        grown = np.empty(2 * top, np.int64)
        grown[:top] = stack
        stack = grown
    stack[top] = idx
    return stack, top + 1


# --- enclosed unknown regions of the reference map (once per map) -----------------------------
@njit(cache=True)
def unknown_runs(ref, out_runs):
    """Runs of unknown cells, row by row, as rows (row, first col, last col) of ``out_runs``.
    Writes as many as fit and returns how many there are (call with an empty array to
    count)."""
    n = 0
    height, width = ref.shape
    for row in range(height):
        col = 0
        while col < width:
            if ref[row, col] >= 0:
                col += 1
                continue
            c0 = col
            while col < width and ref[row, col] < 0:
                col += 1
            if n < out_runs.shape[0]:
                out_runs[n, 0], out_runs[n, 1], out_runs[n, 2] = row, c0, col - 1
            n += 1
    return n


@njit(cache=True)
def link_runs(runs, parent):
    """Union-find over runs: runs in adjacent rows that touch, corners included (8-connected
    unknown regions), share a root. Runs are in row order, sorted by column within a row."""
    n = runs.shape[0]
    for k in range(n):
        parent[k] = k
    prev0, prev1 = 0, 0        # runs of the previous row: [prev0, prev1)
    k = 0
    while k < n:
        cur0 = k
        while k < n and runs[k, 0] == runs[cur0, 0]:
            k += 1
        i, j = prev0, cur0
        if prev1 > prev0 and runs[prev0, 0] == runs[cur0, 0] - 1:
            while i < prev1 and j < k:
                if runs[i, 1] <= runs[j, 2] + 1 and runs[j, 1] <= runs[i, 2] + 1:
                    a, b = find_root(parent, i), find_root(parent, j)
                    parent[max(a, b)] = min(a, b)
                if runs[i, 2] < runs[j, 2]:
                    i += 1
                else:
                    j += 1
        prev0, prev1 = cur0, k


@njit(cache=True)
def mark_enclosed(runs, parent, height, width, max_cells, bits):
    """Set the bits of the cells of every unknown region that touches no map border and has at
    most ``max_cells`` cells. Returns the count of cells marked."""
    n = runs.shape[0]
    size = np.zeros(n, np.int64)
    border = np.zeros(n, np.bool_)
    for k in range(n):
        root = find_root(parent, k)
        row, c0, c1 = runs[k, 0], runs[k, 1], runs[k, 2]
        size[root] += c1 - c0 + 1
        if row == 0 or row == height - 1 or c0 == 0 or c1 == width - 1:
            border[root] = True
    marked = 0
    for k in range(n):
        root = find_root(parent, k)
        if border[root] or size[root] > max_cells:
            continue
        for col in range(runs[k, 1], runs[k, 2] + 1):
            test_and_set(bits, runs[k, 0] * width + col)
        marked += runs[k, 2] - runs[k, 1] + 1
    return marked
