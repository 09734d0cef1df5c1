"""Step 1, the beam classifier (paper, Sec. IV-A; docs/algorithm.md, "Step 1"): which beams
of a scan agree with the reference map M and which show a change, and whether the scan as a
whole disagrees with M so much that its pose is probably wrong (the lost check, from the
authors' code).

For each valid beam i the hit point p_i (paper, eq. 1) is compared with the expected points
of the virtual beams cast on M within a window of +-``window_deg`` around it: a detected
change when none lies within the pairing distance D(r_i). Changes are kept only in runs (the
run filter), and the beams within N_skip of a kept change are SKIPPED. ``prepare_beams`` and
``classify_scan`` do it for a scan, on the per-beam arrays of ``_arguments.Beams``; the
other kernels here are their parts, each tested against a plain reference.

Units: points in grid units, (gx, gy) = ((x - ox) / res, (y - oy) / res); per-beam distances
in grid units but the removed-obstacle skip, in metres.
"""

import math

import numpy as np
from numba import njit

from gridmap._kernels import NO_HIT, first_blocked
from gridmap.cells import UNKNOWN

from ._shared import CHANGE, CLEAR_SHIFT, INVALID, SKIPPED, UNCHANGED, beam_rows

# The smallest sine of the angle between a beam and the surface it hits that ``skip_across``
# divides by: a beam that grazes a surface more closely walks no less than a tenth of the way.
MIN_INCIDENCE_SINE = 0.1


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
def prepare_beams(ranges, sensor, layout, settings, beams):
    """The classifier's per-beam inputs in one call: ``valid_ranges``, the directions of the
    virtual beams and, with more than one virtual beam per measured beam, of the measured
    ones, ``beam_endpoints`` and ``beam_distances`` (``skip_across`` with
    ``removed_skip_across``), into ``beams``. ``ranges`` [m] as the scan holds them,
    ``sensor`` (gx, gy, yaw) [grid units, rad]; ``layout``, ``settings``: one-element
    ``LAYOUT`` and ``SETTINGS`` arrays. Returns (valid beams, a bound on the cells any
    evaluator can flag)."""
    lay, st = layout[0], settings[0]
    res, dist = st.res, st.distances
    valid_ranges(ranges, lay.range_min, lay.range_max, beams.ranges, beams.valid)
    beam_directions(sensor[2], lay.angle_min, lay.virtual_step, beams.virtual)
    measured = beams.virtual    # one virtual beam per step: the very same angles
    if st.virtual_ratio != 1:
        beam_directions(sensor[2], np.float64(lay.angle_min), np.float64(lay.angle_increment),
                        beams.measured)
        measured = beams.measured
    n_valid, walked, box = beam_endpoints(beams.ranges, beams.valid, sensor, measured, res,
                                          beams.hits)
    beam_distances(beams.ranges, res, dist, beams.pairing, beams.tol, beams.skip,
                   beams.removed_reach, beams.free_reach)
    if dist[10] > 0.0:
        skip_across(beams.ranges, beams.valid, beams.hits, sensor, beams.skip,
                    beams.removed_reach, ranges.shape[0])
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
def classify_scan(cells, sensor, layout, settings, beams):
    """``cast_virtual``, ``classify``, ``run_filter`` and ``beam_verdicts`` in one call, on what
    ``prepare_beams`` left in ``beams`` (``cells``: ``MapCells``). Returns (detected changes,
    changes kept by the run filter)."""
    lay, st = layout[0], settings[0]
    cast_virtual(cells.ref, cells.clear, sensor, beams.virtual, lay.max_len, beams.expected,
                 beams.found)
    raw = classify(beams.hits, beams.valid, beams.pairing, beams.expected, beams.found,
                   lay.half_window, lay.wrap, beams.change)
    kept = run_filter(beams.change, st.min_run, lay.wrap, beams.keep, beams.hits,
                      st.min_run_width)
    beam_verdicts(beams.valid, beams.keep, st.n_skip, lay.wrap, beams.verdict)
    return raw, kept


@njit(cache=True)
def run_classifier(ranges, sensor, layout, settings, cells, work):
    """Step 1 alone, in one call from Python, for a scan the gate held back whose surfaces
    ``MapUpdater`` confirms: ``prepare_beams`` then ``classify_scan``, into ``work``'s rows
    (``_arguments.Work``). Returns (valid beams, the bound on the cells any evaluator can
    flag, detected changes, changes kept by the run filter)."""
    beams = beam_rows(work)
    n_valid, bound = prepare_beams(ranges, sensor, layout, settings, beams)
    raw, kept = classify_scan(cells, sensor, layout, settings, beams)
    return n_valid, bound, raw, kept


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
