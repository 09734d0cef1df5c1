"""Steps 2 and 3, the changed-cells and unchanged-cells evaluators (paper, Sec. IV-B and
IV-C; docs/algorithm.md, "Step 2", "Step 3" and "Rules this project adds"): the flags a
classified scan gives the cells of M, each cell at most one changed and one unchanged flag.

Changed flags (Sec. IV-B): a detected change's removed-obstacle walk (``_walks``) and its hit
cell when every cell of M within tol(r_i) of it is free (a new obstacle). Unchanged flags
(Sec. IV-C): an agreeing beam's free walk, and the occupied-or-unknown cells among its hit
cell and their 4-neighbours. Not in the paper: the seen-surface guard (the removed-obstacle
walks pass over M's surfaces the scan sees), ``fill_gaps``, the hits that confirm M's
surfaces, and the growth into the unknown (the open unknown cells seen through and hit).
``flag_scan`` makes them all for a scan, in one call; the other kernels here are its parts.
"""

import math

import numpy as np
from numba import njit

from gridmap.cells import FREE, OCCUPIED

from ._shared import (CHANGE, INVALID, SKIPPED, UNCHANGED, behind_occupied, bit_get, clear_bits,
                      hit_cell, is_open_unknown, set_bit, test_and_set)
from ._walks import free_walk_skips, unknown_walks, walk_scan


# --- new obstacles (Sec. IV-B) ----------------------------------------------------------------
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


@njit(cache=True)
def reach_past_gaps(ranges, margin, free_reach):
    """With ``fill_gaps``: each free walk reaches to ``margin`` [m] short of its hit where that
    is further than its reach."""
    for i in range(ranges.shape[0]):
        if margin > 0.0 and margin < ranges[i]:
            free_reach[i] = np.maximum(free_reach[i], 1.0 - margin / ranges[i])


# --- occupied cells hit (Sec. IV-C) -----------------------------------------------------------


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


@njit(cache=True)
def list_unknown_hits(ref, enclosed, sensor, hits, verdict, clear, hit_marks, ch_marks, out):
    """The hit cells of valid beams in open unknown space, each once (``hit_marks``), into
    ``out``; their changed-flag marks are set too, so that no walk of the scan flags the cells
    it hits (``clear_bits`` clears them after the walks). With ``clear``, a cell just behind
    an occupied cell of M as its beam comes (an 8-neighbour on the sensor's side) is left
    out: M's surface, seen from a pose a little off. Returns the count."""
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
        if not is_open_unknown(flat, enclosed, idx) or clear and behind_occupied(
                ref, row, col, hits[i, 0] - sensor[0], hits[i, 1] - sensor[1]):
            continue
        if test_and_set(hit_marks, idx):
            ch_marks[idx >> 3] = ch_marks[idx >> 3] | (1 << (idx & 7))
            out[n] = idx
            n += 1
    return n


@njit(cache=True)
def flag_listed_unchanged(cells, marks, out, n):
    """Unchanged flags for ``cells``, appended to ``out`` from position n unless a cell has one
    already (``marks``). Returns the new count."""
    for k in range(cells.shape[0]):
        if test_and_set(marks, cells[k]):
            out[n] = cells[k]
            n += 1
    return n


# --- steps 2 and 3 in one call ----------------------------------------------------------------
@njit(cache=True)
def flag_scan(cells, sensor, beams, own, removed_select, layout, settings, state, work, guard,
              confirm):
    """The flags of a scan past the lost check, into ``work.changed`` and ``work.unchanged``,
    each cell once (``state``'s marks): the walks made ready (``ready_walks``), every beam's
    walks (``walk_scan``: removed-obstacle, free and unknown walks), the new-obstacle flags
    (after the walks: a free hit cell, which no walk flags), the guard released (the free
    walks' marks are their own: they do not see it), ``fill_gaps``' flags, the unchanged flags
    of the occupied cells hit, the hits that confirm M's surfaces (``confirm``) and the unknown
    hits' marks released, each hit given an unchanged flag. ``cells``: ``MapCells``;
    ``beams``: ``Beams`` (classified); ``own``: ``OwnRays``; ``removed_select``: the verdicts
    the removed-obstacle walks take their CHANGE beams from; ``guard``: the seen-surface
    guard's radius [grid units] (0: none). Returns (changed flags, new-obstacle flags,
    fill_gaps flags, unchanged flags, unknown cells hit)."""
    lay, st = layout[0], settings[0]
    ref, enclosed, hits, verdict = cells.ref, cells.enclosed, beams.hits, beams.verdict
    ch_marks, un_marks, changed, unchanged = (state.changed_marks, state.unchanged_marks,
                                              work.changed, work.unchanged)
    n_guarded, n_hits = ready_walks(cells, sensor, beams, own, removed_select, lay, st, state,
                                    work, guard)
    n, n_un = walk_scan(ref, enclosed, cells.clear, sensor, hits, removed_select,
                        beams.removed_reach, verdict, beams.free_reach, beams.free_skips,
                        beams.into_unknown, beams.unknown_reach, own.expected, lay.walk_room,
                        ch_marks, un_marks, changed, 0, unchanged, 0)
    n_ch = flag_new_obstacles(ref, hits, beams.tol, verdict, ch_marks, changed, n, beams.scratch)
    n_new = n_ch - n
    clear_bits(ch_marks, work.guarded, n_guarded)
    n_gaps = 0
    if st.gap_clearance > 0:
        n_gaps = flag_gaps(ref, hits, verdict, st.gap_clearance, ch_marks, changed, n_ch) - n_ch
        n_ch += n_gaps
    n_un = flag_occupied_unchanged(ref, hits, verdict, un_marks, unchanged, n_un)
    if confirm:
        n_un = flag_hit_surfaces(ref, hits, verdict, un_marks, unchanged, n_un)
    if st.grow_into_unknown:
        clear_bits(ch_marks, work.hits_unknown, n_hits)
        n_un = flag_listed_unchanged(work.hits_unknown[:n_hits], un_marks, unchanged, n_un)
    return n_ch, n_new, n_gaps, n_un, n_hits


@njit(cache=True)
def ready_walks(cells, sensor, beams, own, removed_select, lay, st, state, work, guard):
    """What ``flag_scan`` does before the walks (``lay``, ``st``: the ``LAYOUT`` and
    ``SETTINGS`` records): which beams walk into unknown space and how far
    (``grow_into_unknown``), the seen-surface guard around the hits ``guard_needed`` finds
    near a walk it changes (into ``beams.scratch``), the unknown cells hit listed (their
    changed-flag marks set: no walk flags them), the free walks' reach with ``fill_gaps``, where
    each free walk may start (``free_walk_skips``), and the unchanged-flag marks of the cells
    that take a changed flag this scan cleared (``unmark_changing``, which leaves the new
    obstacles' beams in ``beams.scratch``). Returns (cells guarded, unknown cells hit)."""
    ref, enclosed, hits, verdict = cells.ref, cells.enclosed, beams.hits, beams.verdict
    ch_marks, spacing = state.changed_marks, abs(lay.angle_increment)
    if st.grow_into_unknown:
        unknown_walks(ref, beams.ranges, own.expected, own.directions, own.found,
                      st.unknown_walk_short, beams.into_unknown, beams.unknown_reach)
    else:
        beams.into_unknown[:] = False
    n_guarded = 0
    if guard > 0.0:
        guard_needed(sensor, hits, verdict, removed_select, beams.removed_reach,
                     beams.into_unknown, beams.unknown_reach, guard, spacing, beams.scratch)
        n_guarded = mark_seen_surfaces(ref, enclosed, hits, verdict, guard,
                                       st.guard_radius_unknown, ch_marks, work.guarded,
                                       beams.scratch)
    n_hits = list_unknown_hits(ref, enclosed, sensor, hits, verdict, st.grow_clear,
                               state.hit_marks, ch_marks,
                               work.hits_unknown) if st.grow_into_unknown else 0
    if st.gap_clearance > 0:
        reach_past_gaps(beams.ranges, st.gap_free_margin, beams.free_reach)
    free_walk_skips(sensor, hits, beams.free_reach, verdict, UNCHANGED, spacing, lay.even_wrap,
                    lay.walk_room, beams.free_skips)
    unmark_changing(ref, hits, beams.tol, verdict, st.gap_clearance, ch_marks,
                    state.unchanged_marks, beams.scratch)
    return n_guarded, n_hits
