"""The map updater's steps 2 to 5 written plainly: the reference the fused kernels of
``updater`` (``_scan.process_scan``, ``_flags.flag_scan``, ``_walks.walk_scan``,
``_decide.push_and_decide`` ...) are tested against, as stumpy keeps its naive
implementations beside its tests.

One function per step of docs/algorithm.md, in Python and NumPy, slow and obvious: a walk
lists the cells its segment passes through (``segment_cells``, cut where it crosses the grid's
lines), the rules are loops over beams and cells, a scan's flags are sets of cells
(flat indices ``row * width + col``), the decision is made over the whole map after every
scan. None of the shortcuts of docs/algorithm.md ("Shortcuts that leave the output as it
is"): every walk starts at the sensor and walks alone, the seen-surface guard goes round
every valid hit, every flag is pushed and counted. Nothing here calls the updater's kernels.

Step 1 is the updater's own classifier (``steps.classify_beams``), whose kernels
test_updater_kernels.py checks one by one against references of its own: ``NaiveUpdater``
starts from its verdicts and per-beam distances. Points are in grid units, (gx, gy) =
((x - ox) / res, (y - oy) / res).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from gridmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from updater import BeamVerdict, UpdaterConfig, steps

INVALID, UNCHANGED = int(BeamVerdict.INVALID), int(BeamVerdict.UNCHANGED)
SKIPPED, CHANGE = int(BeamVerdict.SKIPPED), int(BeamVerdict.CHANGE)
NEIGHBOURS_4 = ((0, 0), (1, 0), (-1, 0), (0, 1), (0, -1))


# --- cells ------------------------------------------------------------------------------------
def segment_cells(x0, y0, x1, y1, height, width) -> tuple[np.ndarray, np.ndarray]:
    """The cells (rows, cols) of the map the segment from (x0, y0) to (x1, y1) passes
    through, in order: the one it starts in, then, cut where it crosses the grid's lines,
    the cell holding the middle of each piece of positive length."""
    dx, dy = x1 - x0, y1 - y0
    cuts = [np.zeros(1), np.ones(1)]
    for start, d in ((x0, dx), (y0, dy)):
        if d != 0:
            lines = np.arange(math.floor(min(start, start + d)) + 1,
                              math.floor(max(start, start + d)) + 1)
            cuts.append((lines - start) / d)
    t = np.unique(np.clip(np.concatenate(cuts), 0.0, 1.0))
    mid = ((t[:-1] + t[1:]) / 2)[np.diff(t) > 0]
    cols = np.r_[math.floor(x0), np.floor(x0 + mid * dx)].astype(int)
    rows = np.r_[math.floor(y0), np.floor(y0 + mid * dy)].astype(int)
    on = (rows >= 0) & (rows < height) & (cols >= 0) & (cols < width)
    rows, cols = rows[on], cols[on]
    new = np.r_[True, (rows[1:] != rows[:-1]) | (cols[1:] != cols[:-1])][:rows.size]
    return rows[new], cols[new]


def walk_cells(sensor, hit, reach, drop_last, shape) -> tuple[np.ndarray, np.ndarray]:
    """The cells (rows, cols) from the sensor to the point at ``reach`` of the way to ``hit``,
    without that point's cell when ``drop_last`` and it lies on the map."""
    height, width = shape
    tx = sensor[0] + reach * (hit[0] - sensor[0])
    ty = sensor[1] + reach * (hit[1] - sensor[1])
    rows, cols = segment_cells(sensor[0], sensor[1], tx, ty, height, width)
    if drop_last and 0 <= tx < width and 0 <= ty < height:
        rows, cols = rows[:-1], cols[:-1]
    return rows, cols


def hit_cell(data, x, y) -> int | None:
    """The flat index of the cell holding (x, y), None off the map."""
    row, col = math.floor(y), math.floor(x)
    if 0 <= row < data.shape[0] and 0 <= col < data.shape[1]:
        return row * data.shape[1] + col
    return None


def disc_is_free(data, px, py, rad) -> bool:
    """Every cell meeting the open disc of radius ``rad`` round (px, py) is free (off the map:
    unknown)."""
    h, w = data.shape
    for r in range(math.floor(py - rad) - 1, math.floor(py + rad) + 2):
        for c in range(math.floor(px - rad) - 1, math.floor(px + rad) + 2):
            qx, qy = min(max(px, c), c + 1.0) - px, min(max(py, r), r + 1.0) - py
            if qx * qx + qy * qy < rad * rad:
                if not (0 <= r < h and 0 <= c < w) or data[r, c] != FREE:
                    return False
    return True


def square_is_free(data, px, py, k) -> bool:
    """The square of k cells each way round the cell of (px, py) is on the map and free."""
    h, w = data.shape
    row, col = math.floor(py), math.floor(px)
    return k <= row < h - k and k <= col < w - k and \
        bool((data[row - k:row + k + 1, col - k:col + k + 1] == FREE).all())


def open_unknown(data, enclosed, idx) -> bool:
    """Unknown in M and outside its enclosed regions: space the map may grow into."""
    return data.flat[idx] == UNKNOWN and not enclosed.flat[idx]


def enclosed_regions(data, max_cells) -> np.ndarray:
    """The unknown cells of M in 8-connected regions that touch no border and have at most
    ``max_cells`` cells, by breadth-first search."""
    h, w = data.shape
    seen = np.zeros_like(data, bool)
    out = np.zeros_like(data, bool)
    for r in range(h):
        for c in range(w):
            if data[r, c] >= 0 or seen[r, c]:
                continue
            comp, queue = [], deque([(r, c)])
            seen[r, c] = True
            while queue:
                y, x = queue.popleft()
                comp.append((y, x))
                for dy in (-1, 0, 1):
                    for dx in (-1, 0, 1):
                        yy, xx = y + dy, x + dx
                        if 0 <= yy < h and 0 <= xx < w and not seen[yy, xx] and data[yy, xx] < 0:
                            seen[yy, xx] = True
                            queue.append((yy, xx))
            border = any(y in (0, h - 1) or x in (0, w - 1) for y, x in comp)
            if not border and len(comp) <= max_cells:
                for y, x in comp:
                    out[y, x] = True
    return out


# --- step 2: changed flags --------------------------------------------------------------------
def seen_surfaces(data, enclosed, hits, verdict, radius, unknown_radius) -> set[int]:
    """The seen-surface guard (not in the paper): the cells within ``radius`` of any valid
    hit (to the cell's nearest point) that are occupied, or within ``unknown_radius`` and
    unknown outside the enclosed regions."""
    h, w = data.shape
    out = set()
    for (x, y), v in zip(hits, verdict):
        if v == INVALID:
            continue
        for row in range(max(math.floor(y - radius), 0), min(math.floor(y + radius) + 1, h)):
            for col in range(max(math.floor(x - radius), 0), min(math.floor(x + radius) + 1, w)):
                dx, dy = max(col - x, 0.0, x - col - 1.0), max(row - y, 0.0, y - row - 1.0)
                d2, v_m = dx * dx + dy * dy, data[row, col]
                if (v_m == OCCUPIED and d2 <= radius * radius) or (
                        v_m == UNKNOWN and not enclosed[row, col]
                        and d2 <= unknown_radius * unknown_radius):
                    out.add(row * w + col)
    return out


def walked(data, sensor, hits, reach, chosen, drop_last, wanted) -> list[int]:
    """The cells of the walks of the ``chosen`` beams that ``wanted`` (bool, H x W) holds,
    each once, in the order first met (a beam with ``reach`` <= 0 walks nowhere)."""
    cells = {}
    for i in np.flatnonzero(np.asarray(chosen) & (np.asarray(reach) > 0)):
        rows, cols = walk_cells(sensor, hits[i], reach[i], drop_last, data.shape)
        take = wanted[rows, cols]
        cells.update(dict.fromkeys((rows[take] * data.shape[1] + cols[take]).tolist()))
    return list(cells)


def removed_obstacle_cells(data, sensor, hits, reach, select) -> list[int]:
    """Removed obstacles (Sec. IV-B): the occupied-or-unknown cells from the sensor to p_th
    of each beam ``select`` calls CHANGE, all but the last, in the order first met."""
    return walked(data, sensor, hits, reach, select == CHANGE, True, data != FREE)


def new_obstacle_cells(data, hits, tol, verdict) -> list[int]:
    """New obstacles (Sec. IV-B): the hit cell of each CHANGE beam whose disc of tol(r_i) is
    all free in M."""
    cells = {}
    for i in range(len(hits)):
        if verdict[i] == CHANGE and disc_is_free(data, hits[i, 0], hits[i, 1], tol[i]):
            idx = hit_cell(data, hits[i, 0], hits[i, 1])
            if idx is not None:
                cells.setdefault(idx)
    return list(cells)


def ends_in_unknown(data, expected, directions, found) -> np.ndarray:
    """Per beam: its expected ray stopped at an unknown cell, or left the map (a hair past the
    expected point, where the ray enters the cell)."""
    out = np.zeros(len(found), bool)
    for i in np.flatnonzero(found):
        col = math.floor(expected[i, 0] + 1e-4 * directions[i, 0])
        row = math.floor(expected[i, 1] + 1e-4 * directions[i, 1])
        on_map = 0 <= row < data.shape[0] and 0 <= col < data.shape[1]
        out[i] = not on_map or data[row, col] == UNKNOWN
    return out


def into_unknown(data, beams, short):
    """Which beams look into unknown space (``ends_in_unknown``) and walk to ``short`` [m]
    short of their hit: (bool per beam, the fraction of the way each walks)."""
    ranges = np.asarray(beams.ranges)
    into = ends_in_unknown(data, beams.own_expected, beams.own_direction, beams.own_found)
    into &= ranges > short          # (not a NaN range either)
    reach = np.zeros(len(ranges))
    reach[into] = 1.0 - short / ranges[into]
    return into, reach


def unknown_seen_through(data, enclosed, sensor, hits, into, reach) -> set[int]:
    """The growth into the unknown (not in the paper): the open unknown cells the beams that
    look into unknown space see through, all but the last."""
    return set(walked(data, sensor, hits, reach, into, True, (data == UNKNOWN) & ~enclosed))


def gap_cells(data, hits, verdict, k) -> set[int]:
    """``fill_gaps`` (not in the paper): the hit cells of agreeing beams with a free square of
    k cells each way round them in M."""
    return {hit_cell(data, x, y) for (x, y), v in zip(hits, verdict)
            if v == UNCHANGED and square_is_free(data, x, y, k)}


# --- step 3: unchanged flags ------------------------------------------------------------------
def free_cells(data, sensor, hits, reach, verdict) -> list[int]:
    """Free cells (Sec. IV-C): those from the sensor to ``reach`` of the way to the hit of each
    agreeing beam, in the order first met."""
    return walked(data, sensor, hits, reach, verdict == UNCHANGED, False, data == FREE)


def occupied_cells(data, hits, verdict) -> list[int]:
    """Occupied cells (Sec. IV-C, the authors' variant): every occupied-or-unknown cell of M
    among the hit cell of each agreeing beam and its 4-neighbours."""
    h, w = data.shape
    cells = {}
    for i in range(len(hits)):
        if verdict[i] != UNCHANGED:
            continue
        r0, c0 = math.floor(hits[i, 1]), math.floor(hits[i, 0])
        for dr, dc in NEIGHBOURS_4:
            rr, cc = r0 + dr, c0 + dc
            if 0 <= rr < h and 0 <= cc < w and data[rr, cc] != FREE:
                cells.setdefault(rr * w + cc)
    return list(cells)


def hit_surface_cells(data, hits, verdict) -> set[int]:
    """Hits confirm M's surfaces (not in the paper): the occupied cells among the hit cell and
    its 4-neighbours of each CHANGE or SKIPPED beam whose hit cell is on the map and not free."""
    h, w = data.shape
    cells = set()
    for i in range(len(hits)):
        if verdict[i] not in (CHANGE, SKIPPED):
            continue
        r0, c0 = math.floor(hits[i, 1]), math.floor(hits[i, 0])
        if not (0 <= r0 < h and 0 <= c0 < w) or data[r0, c0] == FREE:
            continue
        for dr, dc in NEIGHBOURS_4:
            rr, cc = r0 + dr, c0 + dc
            if 0 <= rr < h and 0 <= cc < w and data[rr, cc] == OCCUPIED:
                cells.add(rr * w + cc)
    return cells


def unknown_hit_cells(data, enclosed, sensor, hits, verdict, clear: bool = False) -> set[int]:
    """The growth into the unknown: the hit cells of valid beams in open unknown space (with
    ``clear``, none with an occupied 8-neighbour in M that the beam came past: an offset that
    points back towards the sensor)."""
    cells = set()
    for (x, y), v in zip(hits, verdict):
        idx = hit_cell(data, x, y) if v != INVALID else None
        if idx is None or not open_unknown(data, enclosed, idx):
            continue
        if not (clear and _behind_a_surface(data, idx, x - sensor[0], y - sensor[1])):
            cells.add(idx)
    return cells


def _behind_a_surface(data, idx, dx, dy) -> bool:
    """An occupied 8-neighbour in M that a beam along (dx, dy) came past: its offset points
    back towards the sensor."""
    row, col = divmod(idx, data.shape[1])
    return any(data[r, c] == OCCUPIED
               for r in range(max(row - 1, 0), min(row + 2, data.shape[0]))
               for c in range(max(col - 1, 0), min(col + 2, data.shape[1]))
               if (c - col) * dx + (r - row) * dy < 0)


# --- steps 2 and 3 for a scan -----------------------------------------------------------------
def scan_flags(data, enclosed, beams, cfg: UpdaterConfig, res: float):
    """The flags of a classified scan past the lost check (``beams``: ``steps.Classified``),
    the steps one after the other: (changed cells, unchanged cells, open unknown cells hit).

    The seen-surface guard (when the scan kept a change, or grows into the unknown) and the
    open unknown cells hit keep the walks' changed flags off their cells; the guard is lifted
    before ``fill_gaps``. A hit in open unknown space is an unchanged flag (it says the cell is
    not free)."""
    verdict, hits, sensor = beams.verdict, beams.hits, beams.sensor
    select = np.where(verdict == SKIPPED, CHANGE, verdict) if cfg.walk_skipped_beams else verdict
    grow = cfg.grow_into_unknown
    radius = cfg.seen_surface_radius / res
    guarded = set()
    if radius > 0 and (beams.changes or grow):
        guarded = seen_surfaces(data, enclosed, hits, verdict, radius,
                                min(radius, 1.0) if grow else radius)
    hit = unknown_hit_cells(data, enclosed, sensor, hits, verdict,
                            cfg.grow_clear_of_surfaces) if grow else set()
    changed = set(removed_obstacle_cells(data, sensor, hits, beams.removed_reach, select))
    changed |= set(new_obstacle_cells(data, hits, beams.tol, verdict))
    if grow:
        into, reach = into_unknown(data, beams, max(cfg.seen_surface_radius, res))
        changed |= unknown_seen_through(data, enclosed, sensor, hits, into, reach)
    changed -= guarded | hit
    free_reach = np.array(beams.free_reach, float)
    if cfg.fill_gaps:
        changed |= gap_cells(data, hits, verdict,
                             max(1, int(round(cfg.fill_gaps_clearance / res))))
        margin = cfg.fill_gaps_free_margin
        for i, r in enumerate(beams.ranges):
            if 0 < margin < r:
                free_reach[i] = max(free_reach[i], 1.0 - margin / r)
    unchanged = set(free_cells(data, sensor, hits, free_reach, verdict))
    unchanged |= set(occupied_cells(data, hits, verdict)) | hit
    if cfg.confirm_hit_surfaces and beams.changes:
        unchanged |= hit_surface_cells(data, hits, verdict)
    return changed, unchanged, hit


def held_back_flags(data, beams, cfg: UpdaterConfig) -> set[int]:
    """The unchanged flags a scan the gate held back gives with ``gate_confirm``: those of the
    occupied cells it hits, and with ``confirm_hit_surfaces`` those its changes hit."""
    out = set(occupied_cells(data, beams.hits, beams.verdict))
    if cfg.confirm_hit_surfaces and beams.changes:
        out |= hit_surface_cells(data, beams.hits, beams.verdict)
    return out


def is_lost(data, beams, cfg: UpdaterConfig) -> bool:
    """More than ``lost_fraction`` of the valid beams are changes (before the run filter), and
    of the beams whose expected ray ends in known space too."""
    if not (beams.valid > 0 and beams.raw_changes > cfg.lost_fraction * beams.valid):
        return False
    known = ~np.isnan(beams.ranges) & ~ends_in_unknown(data, beams.own_expected,
                                                       beams.own_direction, beams.own_found)
    return bool(known.any() and beams.change[known].sum() > cfg.lost_fraction * known.sum())


# --- step 4: buffers and decision -------------------------------------------------------------
def popcount(values, mask) -> np.ndarray:
    """The set bits of each value's ``mask`` bits."""
    return np.bitwise_count(np.asarray(values, np.int64) & mask)


def decide_all(hist, counts, data, cfg: UpdaterConfig) -> np.ndarray:
    """The decision rule over the whole map (bool, H x W): n_c >= T; or, with
    ``unanimous_min``, a cell observed fewer than T times whose every flag, at least
    ``unanimous_min``, says changed (an occupied cell of M only with no occupied 8-neighbour
    whose recent flags are not all changed); or, with the neighbour support, n_c plus the
    8-neighbours of the same state of M with n >= T reaching T."""
    mask, threshold, few = (1 << cfg.buffer_size) - 1, cfg.threshold, cfg.unanimous_min
    n = popcount(hist, mask).reshape(data.shape)
    counts = counts.reshape(data.shape)
    h, w = data.shape

    def around(plane):
        """How many of each cell's 8-neighbours ``plane`` holds."""
        pad = np.pad(plane.astype(int), 1)
        return sum(pad[1 + dr:1 + dr + h, 1 + dc:1 + dc + w]
                   for dr in (-1, 0, 1) for dc in (-1, 0, 1) if dr or dc)

    changed = n >= threshold
    if few:
        occ = data == OCCUPIED
        still_seen = occ & (counts > 0) & (n < np.minimum(counts, cfg.buffer_size))
        changed |= (n >= few) & (counts < threshold) & (n == counts) & \
            ~(occ & (around(still_seen) > 0))
    if cfg.neighbour_support:
        state = data.astype(int) if cfg.support_exact_state else (data != FREE).astype(int)
        support = np.zeros_like(n)
        pad_strong, pad_state = np.pad(n >= threshold, 1), np.pad(state, 1, constant_values=9)
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                if dr or dc:
                    support += pad_strong[1 + dr:1 + dr + h, 1 + dc:1 + dc + w] & \
                        (pad_state[1 + dr:1 + dr + h, 1 + dc:1 + dc + w] == state)
        changed |= n + support >= threshold
    return changed


def drawn(hits, data, enclosed, cfg: UpdaterConfig) -> np.ndarray:
    """The open unknown cells whose hit buffer holds T hits, or with ``unanimous_min``
    nothing but hits, at least that many (bool, H x W)."""
    mask = (1 << cfg.buffer_size) - 1
    n = popcount(hits, mask).reshape(data.shape)
    h = hits.reshape(data.shape)
    only_hits = (h & (h + 1)) == 0
    out = (n >= cfg.threshold) | ((cfg.unanimous_min > 0) & (n >= cfg.unanimous_min) & only_hits)
    return out & (h > 0) & (data == UNKNOWN) & ~enclosed


# --- step 5: the output map -------------------------------------------------------------------
def output_map(data, decided, enclosed, cfg: UpdaterConfig, drawn_cells=None, hist=None):
    """M with the changed cells flipped and, with the last check, each enclosed unknown
    8-neighbour of a freed cell closed (unless ``hist`` holds a changed flag for it); the
    drawn cells occupied."""
    out = data.copy()
    out[decided & (data == FREE)] = OCCUPIED
    out[decided & (data != FREE)] = FREE
    if cfg.last_check:
        freed = np.pad(decided & (data != FREE), 1)
        h, w = data.shape
        near = np.zeros_like(decided)
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                near |= freed[1 + dr:1 + dr + h, 1 + dc:1 + dc + w]
        close = near & enclosed & ~decided
        if hist is not None:
            close &= (hist.reshape(data.shape) & ((1 << cfg.buffer_size) - 1)) == 0
        out[close] = OCCUPIED
    if drawn_cells is not None:
        out[drawn_cells] = OCCUPIED
    return out


# --- the updater, scan by scan ----------------------------------------------------------------
class NaiveUpdater:
    """Steps 2 to 5 on a reference map, scan by scan. The caller says which scans to process
    and which to confirm (the gate is the updater's own business, and no part of this)."""

    def __init__(self, ref: OccupancyGrid, cfg: UpdaterConfig):
        self.data, self.res, self.origin, self.cfg = ref.data, ref.resolution, ref.origin, cfg
        self.hist = np.zeros(ref.data.size, np.int64)      # the last N_b flags, 1: changed
        self.counts = np.zeros(ref.data.size, np.int64)    # flags ever, without a bound
        self.hits = np.zeros(ref.data.size, np.int64)      # hit buffers, 1: hit
        self.enclosed = np.zeros(ref.data.shape, bool)
        if cfg.last_check:
            max_cells = int(math.floor(cfg.last_check_max_area / ref.resolution**2 + 1e-9))
            self.enclosed = enclosed_regions(ref.data, max_cells)
        self.confirmed: set[int] = set()     # cells held-back scans confirmed since a view

    def classify(self, scan, pose):
        """Step 1, the updater's classifier, from a fresh workspace."""
        sensor = np.array([(pose.x - self.origin[0]) / self.res,
                           (pose.y - self.origin[1]) / self.res, pose.theta])
        return steps.classify_beams(self.data, scan, sensor, self.res, self.cfg,
                                    steps.Workspace())

    def process(self, scan, pose) -> bool:
        """A scan past the gate: False when it is lost (and nothing is flagged)."""
        beams = self.classify(scan, pose)
        if is_lost(self.data, beams, self.cfg):
            return False
        changed, unchanged, hit = scan_flags(self.data, self.enclosed, beams, self.cfg,
                                             self.res)
        self.push(changed, unchanged)
        mask = (1 << self.cfg.buffer_size) - 1
        if self.cfg.grow_into_unknown:
            for idx in changed:
                if open_unknown(self.data, self.enclosed, idx):
                    self.hits[idx] = (self.hits[idx] << 1) & mask
            for idx in hit:
                self.hits[idx] = ((self.hits[idx] << 1) | 1) & mask
        self.confirmed = set()
        return True

    def confirm(self, scan, pose) -> None:
        """A scan the gate held back as a view already taken, with ``gate_confirm``."""
        beams = self.classify(scan, pose)
        if is_lost(self.data, beams, self.cfg):
            return
        cells = held_back_flags(self.data, beams, self.cfg)
        if self.cfg.gate_confirm_once:
            cells -= self.confirmed
            self.confirmed |= cells
        self.push(set(), cells)

    def push(self, changed, unchanged) -> None:
        """The scan's flags into the buffers, the changed ones first, and counted."""
        mask = (1 << self.cfg.buffer_size) - 1
        for idx in changed:
            self.hist[idx] = ((self.hist[idx] << 1) | 1) & mask
        for idx in unchanged:
            self.hist[idx] = (self.hist[idx] << 1) & mask
        for cells in (changed, unchanged):
            self.counts[list(cells)] += 1

    def decided(self) -> np.ndarray:
        return decide_all(self.hist, self.counts, self.data, self.cfg)

    def drawn(self) -> np.ndarray:
        return drawn(self.hits, self.data, self.enclosed, self.cfg)

    def updated_map(self) -> np.ndarray:
        """The output map, for the rules above (not ``spread_removed`` nor
        ``free_with_neighbours``)."""
        return output_map(self.data, self.decided(), self.enclosed, self.cfg,
                          self.drawn() if self.cfg.grow_into_unknown else None,
                          self.hist if self.cfg.unanimous_min else None)
