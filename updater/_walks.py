"""The walks along the beams, for steps 2 and 3 (paper, Sec. IV-B and IV-C; docs/algorithm.md,
"Step 2", "Step 3" and "Shortcuts that leave the output as it is").

A beam walks from the sensor towards its hit, through the cells of M its segment crosses
(gridmap's ``traverse``: the same start, steps and tie-breaking), and flags the cells of one
kind: a detected change's removed-obstacle walk the occupied-or-unknown cells up to p_th,
all but the last (changed flags, Sec. IV-B); an agreeing beam's free walk the free cells up
to ``free_fraction`` of the way (unchanged flags, Sec. IV-C); a beam that looks into M's open
unknown space the open unknown cells it sees through (changed flags; not in the paper: the
growth into the unknown). ``walk_scan`` is what a scan runs: every beam walked once, to the
furthest of its ends, flagging for all its walks, with the shortcuts of docs/algorithm.md
(jumps across M's clear blocks, free walks that start late, walks that start where their
ray entered M's unknown space). ``walk_beams`` walks one kind for the beams a selection
picks, as the walks were made one after the other: the tests check ``walk_scan`` against it
and the updater benchmark times the kinds apart with it.

Each cell is flagged once per scan: its bit in the marks (a bit plane) is set as it is
listed, and a marked cell is passed over.
"""

import math

import numpy as np
from numba import njit

from gridmap._kernels import clear_exit, segment_start, steps_to
from gridmap.cells import FREE, OCCUPIED

from ._classify import ends_in_unknown
from ._shared import CHANGE, CLEAR_SHIFT, UNCHANGED

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


# --- walks into unknown space (not in the paper) ----------------------------------------------


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
def flag_unknown_seen_through(ref, enclosed, clear, sensor, hits, ranges, expected, directions,
                              found, short, marks, cap, into, reach, out, n):
    """The walks into unknown space alone (``walk_beams``, open unknown cells, all but the
    last; ``unknown_walks`` says which beams walk and how far, into ``into`` and ``reach``),
    after the first n of ``out``, each cell once (``marks``). ``walk_scan`` makes these walks
    in a scan, with the others; this form is what the tests check them against. ``clear``:
    as ``walk_beams`` takes it. Returns the new count."""
    unknown_walks(ref, ranges, expected, directions, found, short, into, reach)
    return walk_beams(ref, enclosed, clear, sensor, hits, reach, select=into, want=True,
                      drop_last=True, cap=cap, kind=WALK_OPEN_UNKNOWN, marks=marks, out=out,
                      n=n, skip=NO_SKIPS)
