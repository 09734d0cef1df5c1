"""What the Python side hands the kernels, each field documented once: the scan's layout and
the configuration as structured scalars (a one-element structured array each, ``LAYOUT`` and
``SETTINGS``), the arrays as named tuples (``MapCells``, ``Buffers``, ``Work``), and the
per-beam arrays the kernels name inside a scan (``Beams``, ``OwnRays``).

Why records for the scalars and named tuples for the arrays: numba types a named tuple's
every field at every call (about 0.1 µs a field, and 0.5 µs a tuple), a structured array in
one look-up, and a scan past the gate is one call of a few hundred µs. A kernel takes a
record out of its array once (``st = settings[0]``) and then reads both alike
(``st.threshold``, ``cells.ref``). Units: [m] metres, [rad] radians, [grid
units] lengths in cells, (gx, gy) = ((x - ox) / res, (y - oy) / res); a cell is addressed by
its flat index ``row * width + col``; a bit plane holds a bit per cell, eight to a byte
(``bits[idx >> 3] >> (idx & 7)``). Symbols are docs/algorithm.md's.

No numba here: the package imports this module, the kernels are compiled on first use.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

# The scan's layout (its beams, angles and range limits) with the configuration and the
# resolution: the same for every scan of a sensor, so worked out once (``steps.Workspace``).
LAYOUT = np.dtype([
    ("range_min", np.float64),        # [m] a valid range is at least this: the scan's range_min
    ("range_max", np.float64),        # [m] ... and below this: min(max_range, scan's range_max)
    ("angle_min", np.float64),        # [rad] theta_0: beam 0's angle from the sensor's heading
    ("angle_increment", np.float64),  # [rad] dtheta: from one measured beam to the next
    ("virtual_step", np.float64),     # [rad] from one virtual beam to the next: dtheta / ratio
    ("max_len", np.float64),          # [grid units] a virtual beam's length: max range + margin
    ("half_window", np.int64),        # [virtual beams] the comparison window's half width
    ("wrap", np.bool_),               # the scan covers 360 deg: window and run filter wrap round
    ("even_wrap", np.bool_),          # ... evenly spaced across its ends too (free walks' skips)
    ("walk_room", np.int64),          # [cells] the most cells one walk lists: 2 max_len + 8,
                                      # or the workspace's room if larger
], align=True)

# The range-dependent distances' parameters, in this order, as ``UpdaterConfig`` names them
# (``SETTINGS``' ``distances``; ``_classify.beam_distances`` reads them by position).
DISTANCES = ("pairing_distance_near", "pairing_range_near", "pairing_distance_slope",
             "pairing_distance_max", "radius_near", "radius_far", "radius_far_range",
             "removed_skip_fraction", "removed_skip_min", "free_fraction", "removed_skip_across")

# What the kernels take from the configuration and the resolution alone (``steps.Settings``).
SETTINGS = np.dtype([
    ("res", np.float64),              # [m] a cell's side
    ("distances", np.float64, (len(DISTANCES),)),  # D(r), tol(r), the skip: ``DISTANCES``
    ("virtual_ratio", np.int64),      # virtual beams per measured beam
    ("min_run", np.int64),            # [beams] the run filter keeps runs of this many changes
    ("min_run_width", np.float64),    # [grid units] ... or of 2 whose end hits lie this far apart
    ("n_skip", np.int64),             # [beams] N_skip: beams beside a kept change are SKIPPED
    ("lost_fraction", np.float64),    # a scan with more changes than this share of beams is lost
    ("walk_skipped_beams", np.bool_),  # SKIPPED beams walk for removed obstacles too
    ("guard_radius", np.float64),     # [grid units] the seen-surface guard's radius (0: off)
    ("guard_radius_unknown", np.float64),  # [grid units] ... around open unknown cells
    ("grow_into_unknown", np.bool_),  # the map grows into M's open unknown space
    ("unknown_walk_short", np.float64),  # [m] walks into unknown space stop this short of the hit
    ("grow_clear", np.bool_),         # no hit flag just behind an occupied cell of M
    ("gap_clearance", np.int64),      # [cells] fill_gaps' free square, each way (0: off)
    ("gap_free_margin", np.float64),  # [m] with fill_gaps, free walks reach this short of the hit
    ("confirm_hit_surfaces", np.bool_),  # hits on M's surfaces confirm them, whatever the verdict
    ("buffer_mask", np.int64),        # the flag bits of a buffer: (1 << N_b) - 1
    ("threshold", np.int64),          # T: changed flags among the last N_b that change a cell
    ("unanimous_min", np.int64),      # a cell seen < T times changes on this many flags, all
                                      # of them changed (0: off)
    ("support_mode", np.int64),       # neighbour support: 0 none, 1 two states, 2 M's value
    ("count_shift", np.int64),        # the bit a cell's flag count starts at (0: ``seen``)
    ("settled_bound", np.int64),      # a free cell's buffer of unchanged flags is settled from
                                      # this (count << count_shift) on (``_buffers.settled``)
], align=True)


class MapCells(NamedTuple):
    """The reference map M, fixed for a session."""

    ref: np.ndarray        # int8 (H, W): 0 free, 100 occupied, -1 unknown
    clear: np.ndarray      # uint8 blocks of 8 x 8 cells: how far M is all free (clear_blocks)
    enclosed: np.ndarray   # bit plane: unknown cells of M's enclosed regions (the last check)


class Buffers(NamedTuple):
    """The updater's state that a scan changes (flat over the map's cells)."""

    hist: np.ndarray             # uint16: the last N_b flags (1: changed), and above them the
                                 # flag count when ``count_shift`` > 0
    seen: np.ndarray             # uint8: the flag counts when they have an array of their own
                                 # (empty when they are above the flags or not kept)
    decided: np.ndarray          # bit plane: the decision rule says changed
    changed_marks: np.ndarray    # bit plane: a changed flag this scan; between scans, a buffer
                                 # full of changes
    unchanged_marks: np.ndarray  # bit plane: an unchanged flag this scan; between scans, a free
                                 # cell whose buffer is settled
    hit_marks: np.ndarray        # bit plane: hit this scan in open unknown space (empty: no growth)
    drawn: np.ndarray            # bit plane: open unknown cells hit often enough to be drawn
    tile_directory: np.ndarray   # int32 (H / 64, W / 64): each block's hit-buffer tile, -1: none
    tile_pool: np.ndarray        # uint16 (tiles, 4096): the hit buffers of the growth into the
                                 # unknown, N_b flags each (1: hit)
    tiles_used: np.ndarray       # int64 (1,): the pool's tiles in use


class Work(NamedTuple):
    """The per-scan workspace (``steps.Workspace``): sized by the scan, never by the map."""

    floats: np.ndarray     # float64 (8, n): per-beam rows, named by ``Beams``
    bools: np.ndarray      # bool (5, n): per-beam rows
    verdicts: np.ndarray   # int8 (2, n): per-beam rows
    points: np.ndarray     # float64 (2, n, 2): per-beam points and directions
    rays: np.ndarray       # float64 (2, m, 2): per virtual beam, m = n * virtual_ratio
    found: np.ndarray      # bool (m,): the virtual beam met a cell of M that is not free
    guarded: np.ndarray    # int32: cells the seen-surface guard marked, to clear them after
    hits_unknown: np.ndarray  # int32 (n,): hit cells in open unknown space
    changed: np.ndarray    # int32: the scan's changed flags, cells in the order flagged
    unchanged: np.ndarray  # int32: ... its unchanged flags
    moved: np.ndarray      # int32: cells whose decision inputs changed (-1 - idx: n_c crossed T)
    missing_tiles: np.ndarray  # int64 (n,): hit-buffer tiles the scan's hits need and lack


class Beams(NamedTuple):
    """A scan's per-beam arrays, views of ``Work``'s rows (``_scan.beam_rows``): n measured
    beams, m = n * virtual_ratio virtual ones."""

    ranges: np.ndarray         # [m] r_i, float64, NaN for an invalid beam
    pairing: np.ndarray        # [grid units] D(r_i), the pairing distance
    tol: np.ndarray            # [grid units] tol(r_i), the new-obstacle radius
    skip: np.ndarray           # [m] |p_i - p_th|: what the removed-obstacle walk leaves out
    removed_reach: np.ndarray  # the removed-obstacle walk ends at this fraction of the way to
                               # the hit: 1 - skip / r_i
    free_reach: np.ndarray     # the free walk ends at this fraction (free_fraction, or further
                               # with fill_gaps)
    unknown_reach: np.ndarray  # the walk into unknown space ends at this fraction (0: none)
    free_skips: np.ndarray     # [grid units] a free walk may start this far from the sensor
    valid: np.ndarray          # bool: a valid range
    change: np.ndarray         # bool: a detected change, before the run filter
    keep: np.ndarray           # bool: ... kept by the run filter
    into_unknown: np.ndarray   # bool: the beam walks into unknown space
    scratch: np.ndarray        # bool: the hits the guard needs, then the new obstacles' beams
    verdict: np.ndarray        # int8: a ``BeamVerdict`` per beam
    skipped_as_change: np.ndarray  # int8: the verdicts, SKIPPED read as CHANGE
                                   # (walk_skipped_beams)
    hits: np.ndarray           # (n, 2) [grid units] p_i, the hit points; NaN when invalid
    measured: np.ndarray       # (n, 2) (cos, sin) of the measured beams (virtual_ratio > 1)
    virtual: np.ndarray        # (m, 2) (cos, sin) of the virtual beams
    expected: np.ndarray       # (m, 2) [grid units] where each virtual beam met M
    found: np.ndarray          # (m,) bool: ... met a cell of M that is not free within max_len


class OwnRays(NamedTuple):
    """The measured beams' own virtual beams (every ``virtual_ratio``-th), for the lost check
    and the walks into unknown space."""

    expected: np.ndarray       # (n, 2) [grid units]
    directions: np.ndarray     # (n, 2) (cos, sin)
    found: np.ndarray          # (n,) bool


def layout_record(scan, cfg, res: float) -> np.ndarray:
    """``LAYOUT`` of a scan (a ``gridmap.Scan``) under a configuration and resolution, as a
    one-element structured array; its ``walk_room`` is this scan's own need (the workspace
    puts its room there)."""
    n = scan.beams
    ratio = cfg.virtual_to_measured_ratio
    range_max = min(cfg.max_range, scan.range_max)
    max_len = (range_max + cfg.cast_margin) / res
    step = scan.angle_increment / ratio
    # a window wider than the scan searches nothing more; a tiny angle_increment (1e-12 rad)
    # would otherwise ask the kernel for 1e11 beams, holding the interpreter for hours (and
    # below 1e-308 the quotient is inf, which no integer holds)
    span = math.radians(cfg.window_deg) / abs(step) if n else 0.0
    half = n * ratio if span >= n * ratio else int(math.floor(span + 1e-9))
    wrap = scan.covers_full_circle()
    even = wrap and abs(scan.fov() - 2 * math.pi) <= 0.05 * abs(scan.angle_increment)
    out = np.zeros(1, LAYOUT)
    out[0] = (float(scan.range_min), range_max, scan.angle_min, scan.angle_increment, step,
              max_len, half, wrap, even, 2 * int(math.ceil(max_len)) + 8)
    return out
