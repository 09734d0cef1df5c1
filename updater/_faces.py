"""Faces a few cells off (not in the paper; docs/algorithm.md, "Faces a few cells off").

A face of M two or three cells from the world's pairs with it within D(r), so the paper's
rules read the beams that hit the world's face as unchanged and leave M's copy standing;
and a face drawn in pieces keeps its gaps, since the hits in them fall within tol(r) of the
pieces. Neither rule looks at where, within the pairing distance, the hits land. This one
does: over the processed scans it counts, per cell, the scans whose beams end in the cell
(``hits``) and the scans whose beams cross it within the last ``band`` cells before their
hit, meeting the surface they hit at a steep enough angle (``passes``), each scan at most
once per cell. At the output, an occupied cell of M that beams keep crossing and almost
never end in is freed, and a free or unknown cell of M near its surfaces that beams keep ending in and
almost never cross is drawn: the face moves to where the scans see it.

Only beams that meet the surface at ``min_sine`` or more count as crossing: a ray grazing a
face under a pose a few centimetres off crosses its cells in most scans while the face
stands. Counts saturate at 255.
"""

import math

import numpy as np
from numba import njit

from gridmap.cells import FREE, OCCUPIED

from ._shared import bit_get, test_and_set

SATURATED = 255
STEPS_PER_CELL = 4          # samples per cell along a beam's last ``band`` cells


@njit(cache=True)
def count_faces(hit_points, sensor, band, min_sine, hits, passes, behind, marks, listed, now,
                crossed):
    """One processed scan into the counts. ``hit_points`` (n, 2) [grid units], NaN for an
    invalid beam; ``sensor`` (gx, gy, yaw); ``band`` [cells]; ``hits``, ``passes``,
    ``behind``: uint8 (H, W); ``marks``: a bit plane, all clear (cleared again before
    returning); ``listed``: int64 room for n * (2 * STEPS_PER_CELL * band + 1) cells.
    ``behind`` counts the cells within ``band`` cells past a beam's hit, along the beam,
    whatever the angle: a surface stands in front of them. Each cell counts once per scan, as
    the first of hit, behind and crossed that it is (``_count_hits``, ``_count_along``,
    ``_count_crossed``). ``now`` and ``crossed``: bit planes of the cells hit and of those
    counted as crossed in this session (set here, never cleared: the session's own). Returns
    the count of cells counted."""
    height, width = hits.shape
    n_listed = _count_hits(hit_points, hits.reshape(-1), width, height, marks, listed, now)
    for i in range(hit_points.shape[0]):
        x, y = hit_points[i, 0], hit_points[i, 1]
        if math.isnan(x) or math.isnan(y):
            continue
        d = math.hypot(x - sensor[0], y - sensor[1])
        if d > 0.0:
            n_listed = _count_along(x, y, (x - sensor[0]) / d, (y - sensor[1]) / d, band,
                                    math.inf, behind.reshape(-1), width, height, marks,
                                    listed, n_listed)
    n_before = n_listed
    n_listed = _count_crossed(hit_points, sensor, band, min_sine, passes.reshape(-1), width,
                              height, marks, listed, n_listed)
    for k in range(n_before, n_listed):
        test_and_set(crossed, listed[k])
    for k in range(n_listed):
        idx = listed[k]
        marks[idx >> 3] = marks[idx >> 3] & ~(1 << (idx & 7))
    return n_listed


@njit(cache=True)
def _count_hits(hit_points, counts, width, height, marks, listed, now):
    """The cells the scan's valid hits lie in, each counted once (``counts``, flat), listed,
    and set in ``now``. Returns how many were listed."""
    n_listed = 0
    for i in range(hit_points.shape[0]):
        x, y = hit_points[i, 0], hit_points[i, 1]
        if math.isnan(x) or math.isnan(y):
            continue
        col, row = int(math.floor(x)), int(math.floor(y))
        if 0 <= col < width and 0 <= row < height:
            idx = row * width + col
            test_and_set(now, idx)
            n_listed = _count_once(idx, counts, marks, listed, n_listed)
    return n_listed


@njit(cache=True)
def _count_crossed(hit_points, sensor, band, min_sine, counts, width, height, marks, listed,
                   n_listed):
    """The cells crossed within ``band`` cells before the hit by each beam that meets the line
    through the hits of beams i - 2 and i + 2 (both valid, within 8 cells of each other) at
    ``min_sine`` or more (``_count_along`` back towards the sensor, not past it)."""
    for i in range(2, hit_points.shape[0] - 2):
        x, y = hit_points[i, 0], hit_points[i, 1]
        xa, ya = hit_points[i - 2, 0], hit_points[i - 2, 1]
        xb, yb = hit_points[i + 2, 0], hit_points[i + 2, 1]
        if math.isnan(x) or math.isnan(xa) or math.isnan(xb):
            continue
        tx, ty = xb - xa, yb - ya
        tn = math.hypot(tx, ty)
        dx, dy = x - sensor[0], y - sensor[1]
        d = math.hypot(dx, dy)
        if tn <= 0.0 or tn > 8.0 or d <= 0.0:
            continue
        ux, uy = dx / d, dy / d
        if abs(ux * ty - uy * tx) / tn >= min_sine:
            n_listed = _count_along(x, y, -ux, -uy, band, d, counts, width, height, marks,
                                    listed, n_listed)
    return n_listed


@njit(cache=True, inline="always")
def _count_along(x, y, ux, uy, band, reach, counts, width, height, marks, listed, n_listed):
    """Count (``counts``, flat) the cells of the points 1/STEPS_PER_CELL ... ``band`` cells
    from the hit (x, y) along (ux, uy), closer than ``reach``, but for the hit's own cell and
    the cells the scan counted already (``marks``; each newly counted one listed). Returns
    the new length of ``listed``."""
    hit_col, hit_row = int(math.floor(x)), int(math.floor(y))
    for k in range(1, STEPS_PER_CELL * band + 1):
        s = k / STEPS_PER_CELL
        if s >= reach:
            break
        col, row = int(math.floor(x + s * ux)), int(math.floor(y + s * uy))
        if (col == hit_col and row == hit_row) or not (0 <= col < width and 0 <= row < height):
            continue
        n_listed = _count_once(row * width + col, counts, marks, listed, n_listed)
    return n_listed


@njit(cache=True, inline="always")
def _count_once(idx, counts, marks, listed, n_listed):
    """Count cell ``idx`` (saturating) unless the scan counted it already (``marks``), listing
    it to clear its mark after the scan. Returns the new length of ``listed``."""
    if test_and_set(marks, idx):
        listed[n_listed] = idx
        n_listed += 1
        if counts[idx] < SATURATED:
            counts[idx] += 1
    return n_listed


@njit(cache=True)
def move_faces(ref, out, counts, planes, band, min_passes, free_ratio, min_hits, draw_ratio,
               confirm, beside_large, large_min_hits):
    """The output (``out``, int8 (H, W), M with the other rules' changes) with the faces moved.
    ``counts``: (hits, passes, behind), uint8 (H, W) each; ``planes``: the bit planes (now,
    crossed, confirmed, candidates, small). Only faces of small structures of M (``small``:
    ``small_structures``) move: a wall's or a rack's stays where M has it, however a
    recording's poses lie along it. The candidates: an occupied cell of M (``ref``) of a
    small structure that ``out`` keeps occupied, crossed by ``min_passes`` scans or more, and
    ended in or stood behind a hit by at most ``free_ratio`` of that many (the back of a
    wall, crossed by a beam a pose error put behind it, stands behind the face that the other
    beams hit), and crossed by a beam of this session (``crossed``: the counts carried from
    earlier sessions would otherwise confirm themselves in a session that never looked), to be
    freed; a free or unknown cell of M that ``out`` keeps so (behind a face
    of M the world's face stands in M's unknown), ended in by ``min_hits`` scans or more and
    crossed by at most ``draw_ratio`` of that many, whose nearest occupied cell of M lies 2
    to ``band`` cells away (Chebyshev; one cell away it is the same face, within the
    scoring's and the map's own slack, and further than ``band`` it is the paper's new
    obstacle) and no occupied cell of M within ``band`` that is not of a small structure,
    and which a beam of this session ended in (``now``: the counts carried from
    earlier sessions would otherwise draw again what stood there then), to be drawn; with
    ``beside_large`` a free cell of M so is drawn beside any structure (an object set down in
    front of a wall or a rack) when ended in by ``large_min_hits`` scans or more too, an
    unknown one still only beside small ones. Each
    candidate's bit is set in ``candidates`` (a bit plane, cleared first); ``confirm``: (to
    free, to draw beside small structures only, to draw beside a larger one), with each only
    those candidates also set in ``confirmed`` (the last session's candidates) are so moved.
    Returns (cells freed, cells drawn)."""
    hits, passes, behind = counts
    now, crossed, confirmed, candidates, small = planes
    height, width = ref.shape
    candidates[:] = 0
    freed = drawn = 0
    for row in range(height):
        for col in range(width):
            idx = row * width + col
            m, h, p = ref[row, col], hits[row, col], passes[row, col]
            to, kind = -1, 0
            if m == OCCUPIED and out[row, col] == OCCUPIED:
                if p >= min_passes and h + behind[row, col] <= free_ratio * p and \
                        bit_get(small, idx) and bit_get(crossed, idx):
                    to = FREE
            elif m != OCCUPIED and out[row, col] == m and h >= min_hits and \
                    p <= draw_ratio * h and bit_get(now, idx):
                near, all_small = _nearest_occupied(ref, small, row, col, band)
                if 2 <= near <= band and (all_small or (beside_large and m == FREE
                                                        and h >= large_min_hits)):
                    to, kind = OCCUPIED, 1 if all_small else 2
            if to < 0:
                continue
            test_and_set(candidates, idx)
            if confirm[kind] and not bit_get(confirmed, idx):
                continue
            out[row, col] = to
            if to == FREE:
                freed += 1
            else:
                drawn += 1
    return freed, drawn


@njit(cache=True)
def _nearest_occupied(ref, small, row, col, reach):
    """Chebyshev distance [cells] from (row, col) to the nearest occupied cell of ``ref``
    within ``reach`` (``reach + 1`` when there is none), and whether every occupied cell
    within ``reach`` belongs to a small structure (``small``, a bit plane)."""
    height, width = ref.shape
    nearest, all_small = reach + 1, True
    for ring in range(1, reach + 1):
        for r in range(max(row - ring, 0), min(row + ring + 1, height)):
            edge = r == row - ring or r == row + ring
            step = 1 if edge else 2 * ring
            c = col - ring
            while c <= col + ring:
                if 0 <= c < width and ref[r, c] == OCCUPIED:
                    nearest = min(nearest, ring)
                    if not bit_get(small, r * width + c):
                        all_small = False
                c += step
    return nearest, all_small


@njit(cache=True)
def small_structures(ref, max_cells, small, seen, stack, members):
    """Set in ``small`` (a bit plane) the occupied cells of ``ref`` whose 8-connected
    structure of occupied cells has at most ``max_cells`` cells: objects, not walls or racks.
    ``seen``: a clear bit plane; ``stack``: int64 room for every occupied cell; ``members``:
    int64 room for ``max_cells + 1``. Returns the count of small structures."""
    height, width = ref.shape
    flat = ref.reshape(-1)
    found = 0
    for start in range(flat.size):
        if flat[start] != OCCUPIED or not test_and_set(seen, start):
            continue
        stack[0] = start
        top, n = 1, 0
        while top > 0:
            top -= 1
            idx = stack[top]
            if n <= max_cells:
                members[n] = idx
            n += 1
            row, col = idx // width, idx % width
            for r in range(max(row - 1, 0), min(row + 2, height)):
                for c in range(max(col - 1, 0), min(col + 2, width)):
                    j = r * width + c
                    if flat[j] == OCCUPIED and test_and_set(seen, j):
                        stack[top] = j
                        top += 1
        if n <= max_cells:
            found += 1
            for k in range(n):
                test_and_set(small, members[k])
    return found


__all__ = ["SATURATED", "count_faces", "move_faces", "small_structures"]
