"""A scan past the gate, steps 1 to 4 in one call from Python (docs/algorithm.md, "One scan,
step by step"): a call from Python costs a few µs, which a scan of 180 beams feels.

``process_scan`` runs the classifier (``_classify``, paper Sec. IV-A), the lost check, the
evaluators (``_flags.flag_scan``, Sec. IV-B and IV-C) and the push and decision
(``push_scan``: ``_decide.push_and_decide``, Sec. IV-D, and the hit buffers of the growth into
the unknown). Its arguments are the scan's ranges and sensor pose, the layout and settings
records and the named tuples of ``_arguments``.
"""

import numpy as np
from numba import njit

from ._buffers import make_hit_tiles, missing_hit_tiles, push_hits
from ._classify import classify_scan, prepare_beams, scan_is_lost
from ._decide import push_and_decide
from ._flags import flag_scan
from ._shared import CHANGE, SKIPPED, beam_rows, own_rays

# What ``process_scan`` returns in place of the changed flags when the workspace lacks room
# for a scan's flags
NEEDS_ROOM = -2


@njit(cache=True)
def process_scan(ranges, sensor, layout, settings, cells, state, work):
    """A scan's whole way through the updater past the gate: ``prepare_beams`` and
    ``classify_scan`` (step 1), the lost check (``scan_is_lost``), then for a scan that is not
    lost ``flag_scan`` (steps 2 and 3; the seen-surface guard only when changes were kept, or
    the scan grows into the unknown, and the hits' confirmation of M's surfaces only when
    changes were kept) and ``push_scan`` (step 4). ``ranges`` [m] as the scan holds them;
    ``sensor`` (gx, gy, yaw) [grid units, rad]; ``layout``, ``settings``: one-element
    ``LAYOUT`` and ``SETTINGS`` arrays; ``cells``: ``MapCells``; ``state``: ``Buffers``;
    ``work``: ``Work``, the per-beam arrays ``Beams`` names in its rows. Returns (valid beams,
    detected changes, changes kept by the run filter, the bound on the scan's flags, then
    ``flag_scan``'s five counts and ``push_scan``'s three); the fifth is ``NEEDS_ROOM`` when
    ``work`` lacks room for the bound (and nothing was flagged), -1 for a lost scan."""
    st = settings[0]
    beams = beam_rows(work)
    n_valid, bound = prepare_beams(ranges, sensor, layout, settings, beams)
    raw, kept = classify_scan(cells, sensor, layout, settings, beams)
    n = ranges.shape[0]
    bound = min(bound, cells.ref.size) + n    # and room for an unchanged flag at each hit cell
    head = (np.int64(n_valid), np.int64(raw), np.int64(kept), np.int64(bound))
    if bound > work.changed.shape[0] or bound > work.unchanged.shape[0]:
        return head + (NEEDS_ROOM, 0, 0, 0, 0, 0, 0, 0)
    own = own_rays(beams, n, st.virtual_ratio)
    if scan_is_lost(cells.ref, own.expected, own.directions, own.found, beams.ranges,
                    beams.change, n_valid, raw, st.lost_fraction):
        return head + (-1, 0, 0, 0, 0, 0, 0, 0)
    select = beams.verdict
    if st.walk_skipped_beams:
        for i in range(n):
            beams.skipped_as_change[i] = CHANGE if beams.verdict[i] == SKIPPED else \
                beams.verdict[i]
        select = beams.skipped_as_change
    guard = st.guard_radius if st.guard_radius > 0.0 and (kept > 0 or st.grow_into_unknown) \
        else 0.0
    confirm = st.confirm_hit_surfaces and kept > 0
    n_ch, n_new, n_gaps, n_un, n_hits = flag_scan(cells, sensor, beams, own, select, layout,
                                                  settings, state, work, guard, confirm)
    return head + (n_ch, n_new, n_gaps, n_un, n_hits) + \
        push_scan(cells, settings, state, work, n_ch, n_un, n_hits)


@njit(cache=True)
def push_scan(cells, settings, state, work, n_ch, n_un, n_hits):
    """Step 4 for the flags ``flag_scan`` listed: ``push_and_decide`` if ``work.moved`` has
    room for their entries, then (``grow_into_unknown``) ``push_hits`` once every unknown
    cell hit has its tile (``missing_hit_tiles``, into ``work.missing_tiles``;
    ``make_hit_tiles`` while the pool has room). Returns (the change of the number of changed
    cells, that of the drawn cells, the tiles missing: -1 when ``work.moved`` had no room, and
    neither push was made)."""
    st = settings[0]
    if n_ch + n_un > work.moved.shape[0]:
        return 0, 0, -1
    width = cells.ref.shape[1]
    flat = cells.ref.reshape(-1)
    d_changed = push_and_decide(state, flat, width, work.changed[:n_ch], work.unchanged[:n_un],
                                work.moved, settings)
    grow = st.grow_into_unknown
    hit_cells = work.hits_unknown[:n_hits]
    n_missing = missing_hit_tiles(state.tile_directory, width, hit_cells,
                                  work.missing_tiles) if grow else 0
    if n_missing > 0:
        n_missing = make_hit_tiles(state.tile_directory, state.tile_pool.shape[0],
                                   state.tiles_used, work.missing_tiles[:n_missing])
    d_drawn = 0
    if grow and n_missing == 0:
        d_drawn = push_hits(state.tile_directory, state.tile_pool, width, flat, cells.enclosed,
                            hit_cells, work.changed[:n_ch], st.buffer_mask, st.threshold,
                            st.unanimous_min, state.hit_marks, state.drawn)
    return d_changed, d_drawn, n_missing
