"""Step 4, second half: the decision rule (paper, Sec. IV-D; docs/algorithm.md, "Step 4").

A cell is changed when n_c, the changed flags among its last N_b, reaches T. The authors'
code adds the neighbour support: n_c plus the 8-neighbours of the same state of M whose own
n reaches T (``support_mode``). Not in the paper: with ``unanimous_min``, a cell observed
fewer than T times changes when every flag it got, at least ``unanimous_min`` of them, says
changed (not an occupied cell beside a surface the scans still see, ``confirmed``).
``push_and_decide`` pushes a scan's flags (``_buffers.push_flags``) and decides the cells
whose inputs moved, each once (``decide``); ``decide_all`` decides the whole map (a loaded
state).
"""

import numpy as np
from numba import njit

from gridmap.cells import FREE, OCCUPIED

from ._buffers import push_flags
from ._shared import bit_get, confirmed, flag_count, popcount16, set_bit


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


@njit(cache=True)
def push_and_decide(state, ref, width, changed, unchanged, moved, settings):
    """``push_flags`` then ``decide`` in one call (``state``: ``Buffers``; ``ref``: M, flat;
    ``changed``, ``unchanged``: the scan's flags; ``moved``: room for their entries;
    ``settings``: a one-element ``SETTINGS`` array), the changed-flag marks kept between scans
    on the cells whose buffers are full of changes (``push_flags``' ``settle``) and serving
    the decision as its stamps: those cells stay changed whatever their neighbours do, so the
    decision may take them as done. Returns the change of the number of changed cells."""
    st = settings[0]
    hist, seen, decided = state.hist, state.seen, state.decided
    ch_marks, un_marks = state.changed_marks, state.unchanged_marks
    mask, threshold, few = st.buffer_mask, st.threshold, st.unanimous_min
    shift, full = st.count_shift, st.settled_bound
    # the changed flags' entries first, so that the decision knows which way each crossed
    n_up = push_flags(hist, seen, ref, changed, unchanged[:0], mask, threshold, few, ch_marks,
                      un_marks, moved, shift, full, decided, True)
    n_moved = n_up + push_flags(hist, seen, ref, changed[:0], unchanged, mask, threshold, few,
                                ch_marks, un_marks, moved[n_up:], shift, full, decided, True)
    return decide(hist, seen, ref, decided, moved[:n_moved], width, mask, threshold, few,
                  st.support_mode, ch_marks, shift, n_up, True)
