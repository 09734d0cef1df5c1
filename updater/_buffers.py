"""Step 4, first half: the flags into the buffers (paper, Sec. IV-D; docs/algorithm.md, "Step
4" and "Shortcuts that leave the output as it is").

Each cell of M has a rolling buffer of its last N_b flags, a uint16 shift register
(1: changed), ``hist = ((hist << 1) | flag) & ((1 << N_b) - 1)``, and a count of the flags it
ever got, saturating, for the rule for cells observed few times (above the flags when they
leave room, ``count_shift``, else in ``seen``). ``push_flags`` pushes a scan's flags and lists
the cells whose decision inputs moved, for ``_decide``. Not in the paper: the hit buffers of
the growth into the unknown (N_b flags each, 1: hit), kept in tiles of 64 x 64 cells made
where a scan first hits open unknown space (``hit_tiles.HitTiles``), and the drawn bit of
each such cell.
"""

import numpy as np
from numba import njit

from gridmap.cells import FREE, OCCUPIED

from ._shared import bit_get, confirmed, flag_count, is_open_unknown, popcount16, set_bit
from .hit_tiles import TILE_SHIFT as HIT_TILE_SHIFT

HIT_TILE_MASK = (1 << HIT_TILE_SHIFT) - 1
# ``settled``'s bound past every buffer: none is settled
NEVER_SETTLED = 0x10000


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


# --- hit buffers of the growth into the unknown (not in the paper) ----------------------------


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
