"""The steps of ALGORITHM.md, one function each, in the order a scan goes through them:
``classify_beams`` -> ``flag_changed_cells`` -> ``flag_unchanged_cells`` -> ``push_flags`` ->
``decide``; ``close_outlines`` builds the output map on demand, ``enclosed_unknown`` prepares the
last check once per reference map.

Each function checks what it is given, converts metres to grid units and calls one kernel of
``updater._kernels`` for the whole scan. Points are in grid units, (gx, gy) = ((x - ox) / res,
(y - oy) / res); cells are addressed by flat index ``row * width + col``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gridmap import Scan

from .config import UpdaterConfig


def kernels():
    from . import _kernels  # numba is imported lazily, on first use

    return _kernels


@dataclass
class Beams:
    """The classifier's result for one scan (views into the workspace, valid until the next
    scan). ``verdict`` holds one of INVALID, UNCHANGED, SKIPPED, CHANGE per beam."""

    ranges: np.ndarray     # [m], float64
    hx: np.ndarray         # hit points [grid units]
    hy: np.ndarray
    verdict: np.ndarray    # int8
    valid: int             # valid beams
    raw_changes: int       # detected changes before the run filter
    changes: int           # detected changes kept by the run filter
    flag_capacity: int     # no evaluator can flag more cells than this in this scan


class Workspace:
    """Scratch arrays reused from scan to scan, grown when a scan needs more; nothing here
    outlives a scan. Sizes follow the scan (beams, cells it reaches), never the map."""

    def __init__(self):
        self._beams = -1
        self._virtual = -1
        self._walk = -1
        self._flags = -1
        self._moved = -1
        self._protected = -1

    def for_beams(self, n: int, m: int, walk: int) -> None:
        if n != self._beams:
            self._beams = n
            self.r = np.zeros(n, np.float64)
            self.hx = np.zeros(n, np.float64)
            self.hy = np.zeros(n, np.float64)
            self.valid = np.zeros(n, np.bool_)
            self.change = np.zeros(n, np.bool_)
            self.keep = np.zeros(n, np.bool_)
            self.verdict = np.zeros(n, np.int8)
        if m != self._virtual:
            self._virtual = m
            self.ex = np.zeros(m, np.float64)
            self.ey = np.zeros(m, np.float64)
            self.eok = np.zeros(m, np.bool_)
        if walk > self._walk:
            self._walk = walk
            self.rows = np.zeros(walk, np.int64)
            self.cols = np.zeros(walk, np.int64)

    def for_flags(self, capacity: int) -> None:
        if capacity > self._flags:
            capacity = int(capacity * 1.25) + 64
            self._flags = capacity
            self.changed = np.zeros(capacity, np.int32)
            self.unchanged = np.zeros(capacity, np.int32)

    def for_moved(self, capacity: int) -> None:
        if capacity > self._moved:
            self._moved = int(capacity * 1.25) + 64
            self.moved = np.zeros(self._moved, np.int32)

    def for_protected(self, capacity: int) -> None:
        if capacity > self._protected:
            self._protected = int(capacity * 1.25) + 64
            self.protected = np.zeros(self._protected, np.int32)

    def nbytes(self) -> int:
        return sum(a.nbytes for a in vars(self).values() if isinstance(a, np.ndarray))


def to_grid(sensor_pose, origin, res) -> np.ndarray:
    """(gx, gy, yaw) of a map-frame pose."""
    return np.array([(sensor_pose.x - origin[0]) / res, (sensor_pose.y - origin[1]) / res,
                     sensor_pose.theta], dtype=np.float64)


# --- 1. beam classifier -----------------------------------------------------------------------
def classify_beams(ref: np.ndarray, scan: Scan, sensor: np.ndarray, res: float,
                   cfg: UpdaterConfig, ws: Workspace) -> Beams:
    """Valid beams, hit points, virtual beams cast once each, the windowed comparison with D(r),
    the run filter and the N_skip neighbourhood of the changes. The window and the run filter
    wrap around the scan's ends only when the scan covers 360 degrees."""
    k = kernels()
    n = scan.beams
    ratio = cfg.virtual_to_measured_ratio
    r_hi = min(cfg.max_range, scan.range_max)
    max_len = (r_hi + cfg.cast_margin) / res
    ws.for_beams(n, n * ratio, 2 * int(math.ceil(max_len)) + 8)
    geom = np.array([scan.angle_min, scan.angle_increment, scan.range_min, r_hi])
    n_valid, walk, box = k.beam_endpoints(scan.ranges, sensor, geom, res, ws.r, ws.hx, ws.hy,
                                          ws.valid)
    step = scan.angle_increment / ratio
    k.cast_virtual(ref, sensor, scan.angle_min, step, max_len, ws.ex, ws.ey, ws.eok)
    half = int(math.floor(math.radians(cfg.window_deg) / abs(step) + 1e-9)) if n else 0
    wrap = scan.covers_full_circle()
    dpar = np.array([cfg.pairing_distance_near, cfg.pairing_range_near,
                     cfg.pairing_distance_slope, cfg.pairing_distance_max])
    raw = k.classify(ws.hx, ws.hy, ws.r, ws.valid, ws.ex, ws.ey, ws.eok, ratio, half, wrap,
                     dpar, res, ws.change)
    kept = k.run_filter(ws.change, cfg.min_run, wrap, ws.keep)
    k.beam_verdicts(ws.valid, ws.keep, cfg.n_skip, wrap, ws.verdict)
    capacity = min(walk, box, ref.size)
    ws.for_flags(capacity)
    return Beams(ws.r, ws.hx, ws.hy, ws.verdict, n_valid, raw, kept, capacity)


def is_lost(beams: Beams, cfg: UpdaterConfig) -> bool:
    """More than ``lost_fraction`` of the valid beams disagree with the map (counted before the
    run filter): the pose is probably wrong, so the scan is dropped."""
    return beams.valid > 0 and beams.raw_changes > cfg.lost_fraction * beams.valid


# --- 2. changed-cells evaluator ---------------------------------------------------------------
def flag_changed_cells(ref: np.ndarray, beams: Beams, sensor: np.ndarray, res: float,
                       cfg: UpdaterConfig, marks: np.ndarray, enclosed: np.ndarray,
                       ws: Workspace) -> tuple[int, int]:
    """Changed flags of the detected-change beams into ``ws.changed`` (each cell once):
    new obstacles (hit cell, if M is free within tol(r)) and removed obstacles (occupied or
    unknown cells up to p_th, all but the last; none within ``seen_surface_radius`` of any hit
    of the scan, unless an unknown cell of the ``enclosed`` regions). With ``cfg.fill_gaps``
    also the hit cells of agreeing beams with nothing of M within ``fill_gaps_clearance``
    (counted as new-obstacle flags). Returns (cells flagged, new-obstacle flags)."""
    tpar = np.array([cfg.radius_near, cfg.radius_far, cfg.radius_far_range,
                     cfg.removed_skip_fraction, cfg.removed_skip_min])
    n_protected = 0
    radius = cfg.seen_surface_radius / res
    if radius > 0 and beams.changes:
        side = 2 * int(math.ceil(radius)) + 1
        ws.for_protected(min(beams.hx.shape[0] * side * side, ref.size))
        n_protected = kernels().protect_seen(ref, enclosed, beams.hx, beams.hy, beams.verdict,
                                             radius, marks, ws.protected)
    n, n_new = kernels().flag_changed(ref, beams.hx, beams.hy, beams.ranges, beams.verdict,
                                      sensor, tpar, res, marks, ws.rows, ws.cols, ws.changed)
    if cfg.fill_gaps:
        clearance = max(1, int(round(cfg.fill_gaps_clearance / res)))
        n, n_gap = kernels().flag_gaps(ref, beams.hx, beams.hy, beams.verdict, clearance,
                                       marks, ws.changed, n)
        n_new += n_gap
    if n_protected:
        kernels().clear_marks(marks, ws.protected, n_protected)
    return n, n_new


# --- 3. unchanged-cells evaluator -------------------------------------------------------------
def flag_unchanged_cells(ref: np.ndarray, beams: Beams, sensor: np.ndarray,
                         cfg: UpdaterConfig, marks: np.ndarray, ws: Workspace) -> int:
    """Unchanged flags of the beams the classifier left UNCHANGED into ``ws.unchanged`` (each
    cell once).

    Occupied cells: the code's variant, every occupied-or-unknown cell among the hit cell c(p_i)
    and its 4-neighbours, rather than the paper's (c(p_i) if occupied, else its occupied
    neighbours). With 2 cm of pose noise a hit at a wall lands sometimes just in front of the
    surface and sometimes just inside it; the code's set changes less between these two cases
    than the paper's (one cell when inside, up to three when in front), so a wall cell's buffer
    collects its unchanged flags steadily, which is what protects walls against the stray
    changed flags of grazing beams. Unknown counts as occupied here, as everywhere in detection.

    Free cells: every free cell on the beam up to ``free_fraction`` of its range. With
    ``cfg.fill_gaps``, up to ``fill_gaps_free_margin`` short of the hit where that reaches
    further (beyond 3.75 m at the defaults): a free cell two cells in front of a face, which
    noisy hits sometimes reach, then also gets the unchanged flags of the beams that pass it,
    so ``fill_gaps`` draws it only from hits that land there consistently. Returns the count
    of cells flagged."""
    margin = cfg.fill_gaps_free_margin if cfg.fill_gaps else 0.0
    return kernels().flag_unchanged(ref, beams.hx, beams.hy, beams.ranges, beams.verdict,
                                    sensor, cfg.free_fraction, margin, marks, ws.rows, ws.cols,
                                    ws.unchanged)


# --- buffers and decision ---------------------------------------------------------------------
def buffer_mask(cfg: UpdaterConfig) -> int:
    return (1 << cfg.buffer_size) - 1


def push_flags(hist_flat: np.ndarray, n_changed: int, n_unchanged: int, cfg: UpdaterConfig,
               ch_marks: np.ndarray, un_marks: np.ndarray, ws: Workspace) -> int:
    """Shift the scan's flags into the cells' buffers, changed flags first:
    ``hist = ((hist << 1) | flag) & ((1 << N_b) - 1)``. Only flagged cells are touched. Returns
    the count of entries written to ``ws.moved`` (cells whose count n_c changed)."""
    ws.for_moved(n_changed + n_unchanged)
    return kernels().push_flags(hist_flat, ws.changed, n_changed, ws.unchanged, n_unchanged,
                                buffer_mask(cfg), cfg.threshold, ch_marks, un_marks, ws.moved)


def decide(hist_flat: np.ndarray, ref_flat: np.ndarray, decided: np.ndarray, n_moved: int,
           width: int, cfg: UpdaterConfig, ws: Workspace) -> int:
    """The decision rule (n_c >= T, or n_c plus the 8-neighbours of the same state in M with
    n >= T reaches T) for the cells whose inputs changed this scan. Returns the change of the
    number of changed cells."""
    return kernels().decide(hist_flat, ref_flat, decided, ws.moved, n_moved, width,
                            buffer_mask(cfg), cfg.threshold, cfg.neighbour_support)


def decide_all(hist_flat: np.ndarray, ref_flat: np.ndarray, width: int,
               cfg: UpdaterConfig) -> tuple[np.ndarray, int]:
    """The decision rule over the whole map: (decided bits, count of changed cells)."""
    decided = np.zeros((ref_flat.size + 7) // 8, np.uint8)
    count = kernels().decide_all(hist_flat, ref_flat, decided, width, buffer_mask(cfg),
                                 cfg.threshold, cfg.neighbour_support)
    return decided, int(count)


# --- output and last check --------------------------------------------------------------------
def close_outlines(ref: np.ndarray, decided: np.ndarray, enclosed: np.ndarray,
                   last_check: bool) -> tuple[np.ndarray, int]:
    """The output cells: M with the changed cells flipped (free <-> occupied, unknown seen
    through -> free) and, with ``last_check``, the outline of removed objects closed: each
    8-neighbour of a cell that became free that lies in an enclosed unknown region of M and is
    still unknown becomes occupied. Returns (cells, count closed by the last check)."""
    out = ref.copy()
    closed = kernels().apply_changes(ref.reshape(-1), decided, enclosed, ref.shape[1],
                                     last_check, out.reshape(-1))
    return out, int(closed)


def enclosed_unknown(ref: np.ndarray, max_cells: int) -> tuple[np.ndarray, int]:
    """Bits of the cells of the enclosed unknown regions of M: 8-connected unknown regions that
    touch no map border and have at most ``max_cells`` cells (objects' interiors). Two unknown
    cells that touch only at a corner belong to one region, so a region counts as enclosed only
    if it is sealed against diagonal leaks too. Returns (bits, cells marked)."""
    k = kernels()
    empty = np.zeros(0, np.int32)
    n = k.unknown_runs(ref, empty, empty, empty)
    row, c0, c1 = (np.zeros(n, np.int32) for _ in range(3))
    k.unknown_runs(ref, row, c0, c1)
    parent = np.zeros(n, np.int32)
    k.link_runs(row, c0, c1, parent)
    bits = np.zeros((ref.size + 7) // 8, np.uint8)
    marked = k.mark_enclosed(row, c0, c1, parent, ref.shape[0], ref.shape[1], max_cells, bits)
    return bits, int(marked)
