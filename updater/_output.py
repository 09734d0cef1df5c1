"""Step 5, the output map and the last check (paper, Sec. IV-D and Fig. 7; docs/algorithm.md,
"Step 5" and "Rules this project adds"), made on demand (``MapUpdater.updated_map``).

The output is M with the changed cells flipped (free <-> occupied, unknown seen through ->
free). The last check closes the outline of a removed object: an unknown cell of an enclosed
region of M (an object's interior, ``mark_enclosed``, found once per map) beside a cell that
became free becomes occupied. Not in the paper: the open unknown cells hit often enough are
drawn occupied (``apply_drawn``), a removed object is freed as a whole (``spread_freed``), and
an occupied cell of M is freed only with what stands beside it (``keep_beside_standing``).
"""

import numpy as np
from numba import njit

from gridmap._kernels import find_root
from gridmap.cells import FREE, OCCUPIED, UNKNOWN

from ._shared import bit_get, confirmed, flag_count, popcount16, test_and_set


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
def apply_drawn(drawn, out):
    """The drawn cells become occupied in ``out`` (flat)."""
    for b in range(drawn.shape[0]):
        if drawn[b] == 0:
            continue
        for idx in range(b * 8, min(b * 8 + 8, out.shape[0])):
            if bit_get(drawn, idx):
                out[idx] = OCCUPIED


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
