"""The steps of docs/algorithm.md, one function each, in the order a scan goes through them:
``classify_beams`` -> ``is_lost`` -> ``flag_changed_cells`` -> ``flag_unchanged_cells`` ->
``push_flags`` -> ``decide`` (``push_and_decide``: the two in one call). The rules that are
not in the paper are steps of their own: ``guard_seen_surfaces`` (undone by
``release_seen_surfaces``) around the changed-cells evaluator, ``fill_gaps`` after it,
``flag_hit_surfaces`` after the unchanged-cells evaluator, and the growth into the unknown
(``list_unknown_hits``, ``flag_unknown_seen_through``, ``release_unknown_hits``,
``push_hits``). ``process_scan`` runs them all, from ``classify_beams`` to ``push_hits``, in
one kernel call, as ``MapUpdater`` does for every scan past the gate: each kernel call from
Python has a fixed cost, which a scan of a few hundred beams feels. ``close_outlines`` builds
the output map on demand, ``enclosed_unknown`` prepares the last check once per reference
map.

Each function takes the per-beam quantities from the classifier (computed in its kernel,
with the same operations as the configuration's own methods, ``UpdaterConfig.pairing_distance``
and the like) and calls the kernels of ``updater._kernels`` once each for the whole scan.
Points are in grid units, (gx, gy) = ((x - ox) / res, (y - oy) / res); cells are addressed by
flat index ``row * width + col``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from gridmap import Scan

from .config import UpdaterConfig
from .hit_tiles import HitTiles
from .verdicts import BeamVerdict

SKIPPED, CHANGE = int(BeamVerdict.SKIPPED), int(BeamVerdict.CHANGE)


@functools.cache
def kernels():
    """The kernels module: numba is imported on first use, not with the package. Cached, as
    an import statement costs about as much as a small kernel's call."""
    from . import _kernels

    return _kernels


@dataclass
class Beams:
    """The classifier's result for one scan and the per-beam quantities the evaluators use
    (some are views into the workspace: valid until the next scan). ``verdict`` holds a
    ``BeamVerdict`` per beam; the float arrays are NaN for invalid beams."""

    sensor: np.ndarray      # (gx, gy, yaw) [grid units, rad]
    ranges: np.ndarray      # [m], float64
    hits: np.ndarray        # (N, 2) hit points [grid units]
    pairing: np.ndarray     # D(r_i) [grid units]
    tol: np.ndarray         # tol(r_i) [grid units]
    skip: np.ndarray        # |p_i - p_th| [m]: what the removed-obstacle walk leaves out
    free_reach: np.ndarray  # the free walk ends at this fraction of the way to the hit
    verdict: np.ndarray     # int8
    valid: int              # valid beams
    raw_changes: int        # detected changes before the run filter
    changes: int            # detected changes kept by the run filter
    # per beam, for the lost check: the beam's own expected point, whether its virtual ray
    # found a blocking cell, the ray's direction, and whether the beam is a detected change
    own_expected: np.ndarray | None = None
    own_found: np.ndarray | None = None
    own_direction: np.ndarray | None = None
    change: np.ndarray | None = None
    # the removed-obstacle walk's reach, 1 - skip / r; None: computed from the two
    removed_reach: np.ndarray | None = None
    # for the walks' shortcuts: M's clear blocks (clear_blocks), the angle between two beams
    # [rad] and whether they cover 360 degrees, beam 0 following the last by that angle
    clear: np.ndarray | None = None
    increment: float = 0.0
    wrap: bool = False


class Workspace:
    """Scratch arrays reused from scan to scan, grown when a scan needs more; nothing here
    outlives a scan. Sizes follow the scan (beams, cells it reaches), never the map."""

    def __init__(self):
        self._beams = -1
        self._virtual = -1
        self._walk = -1
        self._flags = -1
        self._moved = 0
        self.moved = np.zeros(0, np.int32)     # grown by the first push that needs room
        self._protected = -1
        self._own = None
        self._layout = self._layout_cfg = None
        self._settings = self._settings_cfg = None
        self.missing_tiles = np.zeros(0, np.int64)
        self.changed = np.zeros(0, np.int32)    # grown by the first scan that needs room
        self.unchanged = np.zeros(0, np.int32)

    # Per beam, one array per type with a row per quantity (the names are views of the rows):
    # each is one argument to ``process_scan``, and an array argument costs a call about 0.1 µs.
    FLOATS = ("r", "pairing", "tol", "skip", "reach", "free_reach", "unknown_reach", "skips")
    BITS = ("valid", "change", "keep", "into", "scratch")
    VERDICTS = ("verdict", "select")
    POINTS = ("hits", "measured")        # (n, 2) each
    RAYS = ("virtual", "expected")       # (m, 2) each, per virtual beam
    # each array of rows, by its attribute, and the names of its rows
    ROWS = (("floats", FLOATS), ("bits", BITS), ("verdicts", VERDICTS), ("points", POINTS),
            ("rays", RAYS))

    def for_beams(self, n: int, m: int, walk: int) -> None:
        if n != self._beams:
            self._beams = n
            self.floats = np.zeros((len(self.FLOATS), n), np.float64)
            self.bits = np.zeros((len(self.BITS), n), np.bool_)
            self.verdicts = np.zeros((len(self.VERDICTS), n), np.int8)
            self.points = np.zeros((len(self.POINTS), n, 2), np.float64)
            for key, names in self.ROWS[:-1]:     # the rays: per virtual beam, below
                for name, row in zip(names, getattr(self, key)):
                    setattr(self, name, row)
        if m != self._virtual:
            self._virtual = m
            self.rays = np.zeros((len(self.RAYS), m, 2), np.float64)
            self.virtual, self.expected = self.rays
            self.found = np.zeros(m, np.bool_)
            self._own = None
        if walk > self._walk:
            self._walk = walk
            self.cells = np.zeros((2, walk), np.int64)    # rows, cols of one walk

    def own(self, ratio: int, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The virtual beams of the n measured beams (every ``ratio``-th): views of their
        expected points, whether each found a blocked cell, and their directions."""
        if self._own is None or self._own[0] != (ratio, n):
            own = slice(None, None, ratio) if ratio != 1 else slice(None)
            self._own = ((ratio, n), (self.expected[own][:n], self.found[own][:n],
                                      self.virtual[own][:n]))
        return self._own[1]

    def for_flags(self, capacity: int) -> None:
        if capacity > self._flags:
            capacity = int(capacity * 1.25) + 64
            self._flags = capacity
            self.changed = np.zeros(capacity, np.int32)
            self.unchanged = np.zeros(capacity, np.int32)

    def for_unknown_hits(self, beams: int) -> None:
        if beams > getattr(self, "_unknown_hits", -1):
            self._unknown_hits = beams
            self.hits_unknown = np.zeros(beams, np.int32)

    def for_missing_tiles(self, n: int) -> np.ndarray:
        """Room for the tiles of n hit cells (``push_hits``)."""
        if n > self.missing_tiles.shape[0]:
            self.missing_tiles = np.zeros(n, np.int64)
        return self.missing_tiles

    def for_moved(self, capacity: int) -> None:
        if capacity > self._moved:
            self._moved = int(capacity * 1.25) + 64
            self.moved = np.zeros(self._moved, np.int32)

    def for_protected(self, capacity: int) -> None:
        if capacity > self._protected:
            self._protected = int(capacity * 1.25) + 64
            self.protected = np.zeros(self._protected, np.int32)

    def layout(self, scan: Scan, cfg: UpdaterConfig, res: float) -> Layout:
        """The scan's ``Layout``, worked out again only when the beams' layout, the
        configuration (the same object) or the resolution changes; the per-beam arrays are
        sized for it."""
        key = (scan.ranges.size, scan.angle_min, scan.angle_increment, scan.range_min,
               scan.range_max, res)
        got = self._layout
        if got is None or got.key != key or self._layout_cfg is not cfg:
            got = Layout.of(scan, cfg, res, key)
            self._layout, self._layout_cfg = got, cfg
        n, ratio = got.key[0], cfg.virtual_to_measured_ratio
        self.for_beams(n, n * ratio, got.walk)
        return got

    def settings(self, cfg: UpdaterConfig, res: float) -> Settings:
        """The configuration's ``Settings`` (kept while the configuration is the same object
        and the resolution the same)."""
        got = self._settings
        if got is None or self._settings_cfg is not cfg or got.res != res:
            got = Settings.of(cfg, res)
            self._settings, self._settings_cfg = got, cfg
        return got

    def nbytes(self) -> int:
        held = list(vars(self).values()) + ([self._settings.dist] if self._settings else [])
        # the per-beam names are views of rows: counted in their arrays
        return sum(a.nbytes for a in held if isinstance(a, np.ndarray) and a.base is None)


@dataclass(frozen=True)
class Layout:
    """What the classifier takes from a scan's layout (its beams, angles and range limits), the
    configuration and the resolution: the same for every scan of a sensor, so worked out once
    (``Workspace.layout``). Each is a few operations, but a scan of a few hundred beams feels
    a dozen of them."""

    key: tuple          # (beams, angle_min, angle_increment, range_min, range_max, res)
    r_hi: float         # [m] a valid range is below it: min(max_range, range_max)
    max_len: float      # [grid units] the virtual beams' length
    step: float         # [rad] between virtual beams
    half: int           # the comparison window's half width [virtual beams]
    wrap: bool          # the scan covers 360 degrees: the window wraps round its ends
    even: bool          # ... with even spacing across its ends too (the free walks' skips)
    walk: int           # [cells] room for one walk's cells

    @classmethod
    def of(cls, scan: Scan, cfg: UpdaterConfig, res: float, key: tuple) -> Layout:
        n = scan.beams
        ratio = cfg.virtual_to_measured_ratio
        r_hi = min(cfg.max_range, scan.range_max)
        max_len = (r_hi + cfg.cast_margin) / res
        step = scan.angle_increment / ratio
        # a window wider than the scan searches nothing more; a tiny angle_increment (1e-12
        # rad) would otherwise ask the kernel for 1e11 beams, holding the interpreter for
        # hours (and below 1e-308 the quotient is inf, which no integer holds)
        span = math.radians(cfg.window_deg) / abs(step) if n else 0.0
        half = n * ratio if span >= n * ratio else int(math.floor(span + 1e-9))
        wrap = scan.covers_full_circle()
        even = wrap and abs(scan.fov() - 2 * math.pi) <= 0.05 * abs(scan.angle_increment)
        return cls(key, r_hi, max_len, step, half, wrap, even,
                   2 * int(math.ceil(max_len)) + 8)


@dataclass(frozen=True)
class Settings:
    """The kernels' parameters that follow from the configuration and the resolution alone,
    worked out once per configuration (``Workspace.settings``)."""

    res: float
    radius: float         # the seen-surface guard's radius [grid units]
    side: int             # the side of its square [cells]
    unknown_guard: float  # ``unknown_guard``
    short: float          # [m] the walks into unknown space stop this far short of the hit
    gaps: int             # fill_gaps' clearance [cells]; 0: off
    mask: int             # the buffers' rules: ``buffer_mask``, ``count_shift``,
    shift: int            # ``settled_bound`` and ``support_mode``
    full: int
    support: int
    # the range-dependent distances' parameters, for ``kernels().beam_distances``
    dist: np.ndarray = field(compare=False)

    @classmethod
    def of(cls, cfg: UpdaterConfig, res: float) -> Settings:
        radius = cfg.seen_surface_radius / res
        gaps = max(1, int(round(cfg.fill_gaps_clearance / res))) if cfg.fill_gaps else 0
        dist = np.array([getattr(cfg, name) for name in kernels().DISTANCES], np.float64)
        return cls(res, radius, 2 * int(math.ceil(radius)) + 1, unknown_guard(cfg, res),
                   max(cfg.seen_surface_radius, res), gaps, buffer_mask(cfg), count_shift(cfg),
                   settled_bound(cfg), support_mode(cfg), dist)


def to_grid(sensor_pose, origin, res) -> np.ndarray:
    """(gx, gy, yaw) of a map-frame pose."""
    return np.array([(sensor_pose.x - origin[0]) / res, (sensor_pose.y - origin[1]) / res,
                     sensor_pose.theta], dtype=np.float64)


def clear_blocks(ref: np.ndarray) -> np.ndarray:
    """The clear blocks of M that casts and walks jump across (``gridmap._kernels``'
    ``clear_blocks``, blocks of 2**CLEAR_SHIFT cells): 1/64 byte a cell."""
    from gridmap import _kernels as grid

    shift = kernels().CLEAR_SHIFT
    out = np.zeros((-(-ref.shape[0] >> shift), -(-ref.shape[1] >> shift)), np.uint8)
    grid.clear_blocks(ref, shift, out)
    return out


# --- 1. beam classifier -----------------------------------------------------------------------
def beam_distances(ranges: np.ndarray, res: float, cfg: UpdaterConfig):
    """The range-dependent distances of docs/algorithm.md for every beam, from the config: D(r_i)
    and tol(r_i) [grid units], and the removed-obstacle skip [m]."""
    return (cfg.pairing_distance(ranges) / res, cfg.new_obstacle_radius(ranges) / res,
            cfg.removed_skip(ranges))


def classify_beams(ref: np.ndarray, scan: Scan, sensor: np.ndarray, res: float,
                   cfg: UpdaterConfig, ws: Workspace, clear: np.ndarray | None = None) -> Beams:
    """Valid beams, hit points, the per-beam distances, virtual beams cast once each, the
    windowed comparison with D(r), the run filter and the N_skip neighbourhood of the changes.
    The window and the run filter wrap around the scan's ends only when the scan covers 360
    degrees. Two kernel calls: the per-beam inputs (``prepare_beams``: valid beams, hit
    points, the distances of ``beam_distances``), then the classifier (``classify_scan``). A
    beam is invalid when its range is not finite, not above 0 (r = 0 is no hit), below the
    scan's range_min, or at or beyond min(max_range, the scan's range_max). ``clear``: M's
    ``clear_blocks`` (None: worked out here)."""
    k = kernels()
    clear = clear_blocks(ref) if clear is None else clear
    n = scan.beams
    ratio = cfg.virtual_to_measured_ratio
    lay = ws.layout(scan, cfg, res)
    n_valid, bound = k.prepare_beams(
        ranges=scan.ranges, r_lo=float(scan.range_min), r_hi=float(lay.r_hi), sensor=sensor,
        angle_min=scan.angle_min, step=lay.step, increment=scan.angle_increment, ratio=ratio,
        res=res, dist=ws.settings(cfg, res).dist, out_r=ws.r, out_valid=ws.valid,
        out_virtual=ws.virtual, out_measured=ws.measured, out_hits=ws.hits,
        out_pairing=ws.pairing, out_tol=ws.tol, out_skip=ws.skip, out_reach=ws.reach,
        out_free_reach=ws.free_reach)
    raw, kept = k.classify_scan(
        ref, clear, sensor, virtual=ws.virtual, max_len=lay.max_len, hits=ws.hits,
        valid=ws.valid, pairing=ws.pairing, half_window=lay.half, wrap=lay.wrap,
        min_run=cfg.min_run, n_skip=cfg.n_skip, out_expected=ws.expected, out_found=ws.found,
        out_change=ws.change, out_keep=ws.keep, out_verdict=ws.verdict,
        min_width=cfg.min_run_width / res)
    # No evaluator can flag more cells than the bound or the map holds; the n more leave room
    # for an unchanged flag at each beam's hit cell.
    ws.for_flags(min(bound, ref.size) + n)
    expected, found, direction = ws.own(ratio, n)
    return Beams(sensor, ws.r, ws.hits, ws.pairing, ws.tol, ws.skip, ws.free_reach,
                 ws.verdict, n_valid, raw, kept, expected, found, direction, ws.change, ws.reach,
                 clear, abs(scan.angle_increment), lay.even)


def is_lost(beams: Beams, cfg: UpdaterConfig, ref: np.ndarray) -> bool:
    """More than ``lost_fraction`` of the valid beams disagree with the map (counted before the
    run filter): the pose is probably wrong, so the scan is dropped (``scan_is_lost``, whose
    rule ``process_scan`` applies too)."""
    return bool(kernels().scan_is_lost(ref, beams.own_expected, beams.own_direction,
                                       beams.own_found, beams.ranges, beams.change, beams.valid,
                                       beams.raw_changes, cfg.lost_fraction))


# --- not in the paper: the seen-surface guard -------------------------------------------------
def guard_seen_surfaces(ref: np.ndarray, beams: Beams, cfg: UpdaterConfig, res: float,
                        marks: np.ndarray, enclosed: np.ndarray, ws: Workspace) -> int:
    """Mark in ``marks`` (the changed-flag marks, so the removed-obstacle walk passes them by)
    the cells of M within ``seen_surface_radius`` of the hit point of any valid beam that are
    occupied, or unknown outside the ``enclosed`` regions: surfaces this scan sees. Under a
    pose error below a cell the rays that graze an object's corner cross its outline cells
    while the beams that hit the object say it is still there (docs/choices.md). Only scans
    with detected changes need it. Returns the count marked, for ``release_seen_surfaces``."""
    st = ws.settings(cfg, res)
    if st.radius <= 0 or not (beams.changes or cfg.grow_into_unknown):
        return 0
    ws.for_protected(min(beams.hits.shape[0] * st.side * st.side, ref.size))
    return kernels().mark_seen_surfaces(ref, enclosed, beams.hits, beams.verdict,
                                        radius=st.radius, unknown_radius=st.unknown_guard,
                                        marks=marks, out=ws.protected)


def unknown_guard(cfg: UpdaterConfig, res: float) -> float:
    """The seen-surface guard's radius [grid units] for open unknown cells: the whole radius
    with the paper's rules; growing into the unknown, one cell at most. There the cells a scan
    hits keep out of its walks anyway (``list_unknown_hits``), and a guard of 1.5 cells kept
    the free space from ever reaching a wall M had not seen (on the Intel log more of the
    well-observed cells stayed unknown than with one cell); none at all let rays grazing a
    rack's corner that M had as unknown free it under 5 cm of pose error."""
    radius = cfg.seen_surface_radius / res
    return min(radius, 1.0) if cfg.grow_into_unknown else radius


def release_seen_surfaces(marks: np.ndarray, n_guarded: int, ws: Workspace) -> None:
    """Clear the marks ``guard_seen_surfaces`` set, and only those."""
    if n_guarded:
        kernels().clear_bits(marks, ws.protected, n_guarded)


# --- 2. changed-cells evaluator ---------------------------------------------------------------
def flag_changed_cells(ref: np.ndarray, beams: Beams, marks: np.ndarray,
                       ws: Workspace) -> tuple[int, int]:
    """Changed flags of the detected-change beams into ``ws.changed``, each cell once
    (``marks``). New obstacles: the hit cell, if every cell of M within tol(r_i) is free.
    Removed obstacles: the occupied or unknown cells from the sensor to p_th, short of the hit
    by the skip, all but the last (cells marked already, as ``guard_seen_surfaces`` marks
    them, get none). Returns (cells flagged, new-obstacle flags)."""
    k = kernels()
    n = k.flag_removed_obstacles(ref, beams.sensor, beams.hits, reach=removed_reach(beams),
                                 verdict=beams.verdict, marks=marks, cells=ws.cells,
                                 out=ws.changed)
    n_all = k.flag_new_obstacles(ref, beams.hits, tol=beams.tol, verdict=beams.verdict,
                                 marks=marks, out=ws.changed, n=n)
    return n_all, n_all - n


# --- not in the paper: fill_gaps --------------------------------------------------------------
def fill_gaps(ref: np.ndarray, beams: Beams, cfg: UpdaterConfig, res: float,
              marks: np.ndarray, ws: Workspace, n: int) -> tuple[int, int]:
    """With ``cfg.fill_gaps``: a hit that pairs with M but lands in a cell with nothing of M
    within ``fill_gaps_clearance`` also gets a changed flag, appended to ``ws.changed`` after
    the first n (each cell once, ``marks``). The pairing distance D(r) otherwise hides the gaps
    of a face that an earlier session mapped only in pieces (docs/choices.md, "fill_gaps").

    The free walk of an agreeing beam then reaches to ``fill_gaps_free_margin`` short of the
    hit where that is further than ``free_fraction`` of its range (beyond 3.75 m at the
    defaults): a free cell two cells in front of a face, which noisy hits sometimes reach, then
    also gets the unchanged flags of the beams that pass it, so this rule draws it only from
    hits that land there consistently. Returns (cells flagged in all, flagged here)."""
    if not cfg.fill_gaps:
        return n, 0
    clearance = ws.settings(cfg, res).gaps
    n_all = kernels().flag_gaps(ref, beams.hits, beams.verdict, clearance=clearance, marks=marks,
                                out=ws.changed, n=n)
    margin = cfg.fill_gaps_free_margin
    if margin > 0:
        longer = margin < beams.ranges
        beams.free_reach[longer] = np.maximum(beams.free_reach[longer],
                                              1.0 - margin / beams.ranges[longer])
    return n_all, n_all - n


# --- 3. unchanged-cells evaluator -------------------------------------------------------------
def flag_unchanged_cells(ref: np.ndarray, beams: Beams, marks: np.ndarray,
                         ws: Workspace) -> int:
    """Unchanged flags of the beams the classifier left UNCHANGED into ``ws.unchanged`` (each
    cell once, ``marks``).

    Occupied cells: the code's variant, every occupied-or-unknown cell among the hit cell c(p_i)
    and its 4-neighbours, rather than the paper's (c(p_i) if occupied, else its occupied
    neighbours). With 2 cm of pose noise a hit at a wall lands sometimes just in front of the
    surface and sometimes just inside it; the code's set changes less between these two cases
    than the paper's (one cell when inside, up to three when in front), so a wall cell's buffer
    collects its unchanged flags steadily, which is what protects walls against the stray
    changed flags of grazing beams. Unknown counts as occupied here, as everywhere in detection.

    Free cells: every free cell on the beam up to ``beams.free_reach`` of the way to the hit
    (``free_fraction``, or further with ``fill_gaps``). Returns the count of cells flagged."""
    k = kernels()
    n = k.flag_free_unchanged(ref, beams.sensor, beams.hits, reach=beams.free_reach,
                              verdict=beams.verdict, marks=marks, cells=ws.cells,
                              out=ws.unchanged)
    return k.flag_occupied_unchanged(ref, beams.hits, beams.verdict, marks, ws.unchanged, n)


def flag_unchanged_surfaces(ref: np.ndarray, beams: Beams, marks: np.ndarray,
                            ws: Workspace) -> int:
    """The occupied half of ``flag_unchanged_cells`` alone: the occupied-or-unknown cells of M
    among the hit cell and its 4-neighbours of each UNCHANGED beam. Returns the count."""
    return kernels().flag_occupied_unchanged(ref, beams.hits, beams.verdict, marks,
                                             ws.unchanged, 0)


# --- not in the paper: hits confirm M's surfaces ---------------------------------------------
def flag_hit_surfaces(ref: np.ndarray, beams: Beams, cfg: UpdaterConfig, marks: np.ndarray,
                      ws: Workspace, n: int) -> int:
    """With ``cfg.confirm_hit_surfaces``: unchanged flags, after the first n of
    ``ws.unchanged`` (each cell once, ``marks``), for the occupied cells of M among the hit
    cell and its 4-neighbours (the set the unchanged-cells evaluator uses) of every detected
    change and every beam within ``n_skip`` of one whose hit lands in a cell that M does not
    have as free.

    The unchanged-cells evaluator hears only the beams that agree with M, so a cell of M
    that the scans hit while their beams count as changes gets no unchanged flag from them.
    Where M is unknown around the robot (a place an earlier session saw only from afar) every
    beam is a change, as no virtual beam gets past the unknown cells: the removed-obstacle
    walks of the scans that look past an occupied cell of M fill its buffer, the unknown
    cells around it, seen through, lend it their support in the decision, and the later scans
    that hit it, the session's own evidence that it is there, cannot empty its buffer again.
    A hit in an occupied or unknown cell of M is such evidence whatever the classifier made of
    the beam. A hit in a free cell of M is not: it pairs with nothing of M, so it may be a new
    object, or noise in front of a face that stood behind a removed object, whose remnants
    beside it should still go (flagging the 4-neighbours of such hits kept a removed object's
    cell in the simulated W2).

    In the main job of the simulated warehouse it changes nothing in W2 and W3 and removes a
    few false changes of W4; in the soak sessions, each run with and without it on the same
    M(i-1), the few cells that differ are mostly remnants of removed objects that some beam
    hit, next to remnants both runs keep; on the Killian Court log (a map of its first third
    updated with its last third) it keeps the cells occupied in both thirds' maps that the
    update used to free (figures: docs/choices.md and benchmarks/RESULTS.md). Returns the new
    count."""
    if not (cfg.confirm_hit_surfaces and beams.changes):
        return n    # no change, so no beam the rule is for
    return int(kernels().flag_hit_surfaces(ref, beams.hits, beams.verdict, marks,
                                           ws.unchanged, n))


# --- not in the paper: growth into the unknown ------------------------------------------------
def list_unknown_hits(ref: np.ndarray, beams: Beams, enclosed: np.ndarray, hit_marks: np.ndarray,
                      ch_marks: np.ndarray, ws: Workspace) -> int:
    """The hit cells of the scan's valid beams that lie in open unknown space of M (unknown,
    outside the enclosed regions) into ``ws.hits_unknown``, kept from the scan's walks (their
    changed-flag marks set until ``release_unknown_hits``). Returns the count."""
    ws.for_unknown_hits(beams.hits.shape[0])
    return int(kernels().list_unknown_hits(ref, enclosed, beams.hits, beams.verdict,
                                           hit_marks=hit_marks, ch_marks=ch_marks,
                                           out=ws.hits_unknown))


def flag_unknown_seen_through(ref: np.ndarray, beams: Beams, enclosed: np.ndarray,
                              cfg: UpdaterConfig, res: float, marks: np.ndarray, ws: Workspace,
                              n: int) -> int:
    """Changed flags, after the first n of ``ws.changed``, for the open unknown cells that the
    beams looking into unknown space (their expected ray ends at an unknown cell) see through,
    up to ``seen_surface_radius`` (at least a cell) short of the hit. The paper's walk frees
    unknown cells too, but only for detected changes and max(2 %, 0.15 m) short of the hit, so
    as not to free a surface a noisy hit stands for; in space M never saw, an agreeing beam
    shows it empty as well, and the hit cells themselves are kept from the walks. Beams whose
    expected ray ends in known space are left out: under a pose error below a cell they graze
    the corners M had as unknown. Returns the new count."""
    short = ws.settings(cfg, res).short
    return int(kernels().flag_unknown_seen_through(
        ref, enclosed, beams.clear, sensor=beams.sensor, hits=beams.hits, ranges=beams.ranges,
        expected=beams.own_expected, directions=beams.own_direction, found=beams.own_found,
        short=short, marks=marks, cap=ws.cells.shape[1], into=ws.into, reach=ws.unknown_reach,
        out=ws.changed, n=n))


def release_unknown_hits(ch_marks: np.ndarray, un_marks: np.ndarray, n_hits: int,
                         ws: Workspace, n_un: int) -> int:
    """Clear the changed-flag marks ``list_unknown_hits`` set, and give each hit cell an
    unchanged flag after the first n_un of ``ws.unchanged`` (a hit says the cell is not free).
    Returns the new count of unchanged flags."""
    cells = ws.hits_unknown[:n_hits]
    kernels().clear_bits(ch_marks, cells, n_hits)
    return int(kernels().flag_listed_unchanged(cells, un_marks, ws.unchanged, n_un))


def push_hits(tiles: HitTiles, ref: np.ndarray, enclosed: np.ndarray, n_hits: int,
              n_changed: int, cfg: UpdaterConfig, res: float, hit_marks: np.ndarray,
              drawn: np.ndarray, ws: Workspace) -> int:
    """The hit buffers of open unknown cells, N_b flags as the change buffers: 1 for a scan
    that hit the cell, 0 for one that saw through it. A cell hit in T of its last N_b
    observations (or, with ``unanimous_min``, hit by every scan that observed it, at least that
    many) is drawn: occupied in the output. Returns the change of the drawn count."""
    hit_cells = ws.hits_unknown[:n_hits]
    # the tiles of the cells hit: checked in a kernel, made (rarely) in NumPy
    missing = ws.for_missing_tiles(n_hits)
    n_missing = kernels().missing_hit_tiles(tiles.directory, ref.shape[1], hit_cells, missing)
    if n_missing:
        tiles.make(missing[:n_missing])
    return int(kernels().push_hits(tiles.directory, tiles.pool, ref.shape[1], ref.reshape(-1),
                                   enclosed, hit_cells=hit_cells,
                                   changed=ws.changed[:n_changed],
                                   mask=ws.settings(cfg, res).mask,
                                   threshold=cfg.threshold, few=cfg.unanimous_min,
                                   hit_marks=hit_marks, drawn=drawn))


def decide_drawn(tiles: HitTiles, ref: np.ndarray, enclosed: np.ndarray, cfg: UpdaterConfig,
                 drawn: np.ndarray) -> int:
    """The drawn bits of every hit buffer (on loading a saved state). Returns the count."""
    return int(kernels().decide_drawn(tiles.directory, tiles.pool, ref.shape[0], ref.shape[1],
                                      ref.reshape(-1), enclosed,
                                      mask=np.uint16(buffer_mask(cfg)), threshold=cfg.threshold,
                                      few=cfg.unanimous_min, drawn=drawn))


# --- a scan past the gate in one call -------------------------------------------------------------
def process_scan(ref: np.ndarray, scan: Scan, sensor: np.ndarray, res: float,
                 cfg: UpdaterConfig, ws: Workspace, clear: np.ndarray,
                 marks: tuple[np.ndarray, np.ndarray, np.ndarray], enclosed: np.ndarray,
                 buffers: tuple[np.ndarray, np.ndarray, np.ndarray], tiles: HitTiles,
                 drawn: np.ndarray) -> tuple[int, int, int, tuple[int, int, int, int, int] | None]:
    """What ``classify_beams``, ``is_lost``, ``guard_seen_surfaces``, ``list_unknown_hits``
    (with ``grow_into_unknown``), ``flag_changed_cells``, ``flag_unknown_seen_through``,
    ``release_seen_surfaces``, ``fill_gaps``, ``flag_unchanged_cells``, ``flag_hit_surfaces``
    and ``release_unknown_hits`` do one after the other, then ``push_and_decide`` and
    ``push_hits``, in one kernel call (``marks``: the changed-flag, unchanged-flag and hit
    marks; ``buffers``: the buffers and counts, of the map's shape, and the decided bits;
    ``clear``: M's ``clear_blocks``). The call is made again when the workspace lacks room
    for the scan's flags (it then flags nothing); the pushes are left to calls of their own
    when it lacks room for the flags' entries, or a hit cell its tile. Returns (valid beams,
    detected changes, changes kept by the run filter, then None for a lost scan, else
    (changed flags, new-obstacle and fill_gaps flags, unchanged flags, the change of the
    number of changed cells, that of the drawn cells)); the classifier's arrays stay in
    ``ws``."""
    k, lay, st, n = kernels(), ws.layout(scan, cfg, res), ws.settings(cfg, res), scan.beams
    ws.for_protected(min(n * st.side * st.side, ref.size) if st.radius > 0 else 0)
    ws.for_unknown_hits(n)
    missing = ws.for_missing_tiles(n)
    (ch_marks, un_marks, hit_marks), (hist, seen, decided) = marks, buffers
    while True:
        got = k.process_scan(
            scan.ranges, float(scan.range_min), lay.r_hi, sensor, scan.angle_min, lay.step,
            scan.angle_increment, cfg.virtual_to_measured_ratio, res, st.dist, ws.floats,
            ws.bits, ws.verdicts, ws.points, ws.rays, ws.found, ref, clear, lay.max_len,
            lay.half, lay.wrap, cfg.min_run, cfg.n_skip, cfg.min_run_width / res,
            cfg.lost_fraction, cfg.walk_skipped_beams, st.radius, st.unknown_guard,
            cfg.grow_into_unknown, st.short, st.gaps, cfg.fill_gaps_free_margin,
            cfg.confirm_hit_surfaces, ws.cells.shape[1], lay.even, ch_marks, un_marks,
            hit_marks, ws.protected, ws.hits_unknown, ws.changed, ws.unchanged, hist, seen,
            decided, st.mask, cfg.threshold, cfg.unanimous_min, st.support, ws.moved, st.shift,
            st.full, tiles.directory, tiles.pool, tiles.count, drawn, missing, enclosed)
        if got[4] != k.NEEDS_ROOM:
            break
        ws.for_flags(got[3])
    n_valid, raw, kept, _, n_ch, n_new, n_gaps, n_un, n_hits, d_changed, d_drawn, n_missing = got
    if n_ch < 0:
        return n_valid, raw, kept, None
    if n_missing < 0:           # no room for the flags' entries: the pushes, one by one
        d_changed = push_and_decide(hist.reshape(-1), seen.reshape(-1), ref.reshape(-1),
                                    decided, n_ch, n_un, ref.shape[1], cfg, res, ch_marks,
                                    un_marks, ws)
    if n_missing != 0 and cfg.grow_into_unknown:
        d_drawn = push_hits(tiles, ref, enclosed, n_hits, n_ch, cfg, res, hit_marks, drawn, ws)
    return n_valid, raw, kept, (n_ch, n_new + n_gaps, n_un, d_changed, d_drawn)


def removed_reach(beams: Beams) -> np.ndarray:
    """p_th as a fraction of the way to the hit, per beam: where the removed-obstacle walk
    ends."""
    if beams.removed_reach is not None:
        return beams.removed_reach
    return 1.0 - beams.skip / beams.ranges


# --- buffers and decision ---------------------------------------------------------------------
def buffer_mask(cfg: UpdaterConfig) -> int:
    return (1 << cfg.buffer_size) - 1


def count_shift(cfg: UpdaterConfig) -> int:
    """Where each cell's flag count lives: 0 in an array of its own (or nowhere, when the flags
    are not counted: ``unanimous_min`` 0), else the bit of the buffer the count starts at,
    N_b. The rule reads the count up to N_b (the last min(count, N_b) flags tell a surface the
    scans still see), so the spare bits hold it when they count to N_b: N_b <= 12."""
    if not cfg.unanimous_min or (0xFFFF >> cfg.buffer_size) < cfg.buffer_size:
        return 0
    return cfg.buffer_size


def settled_bound(cfg: UpdaterConfig) -> int:
    """``settled``'s bound: from which buffer on an unchanged flag into a free cell's buffer of
    unchanged flags changes nothing. 0 when no count is kept; else the count T, shifted to its
    bits: the rules read a free cell's count only against T (``decide``: observed fewer than T
    times; the others read the counts of occupied cells); none (``NEVER_SETTLED``) when the
    count has an array of its own."""
    if not cfg.unanimous_min:
        return 0
    shift = count_shift(cfg)
    full = cfg.threshold << shift
    return full if shift and full <= 0xFFFF else kernels().NEVER_SETTLED


def settled_marks(ref: np.ndarray, hist: np.ndarray, cfg: UpdaterConfig) -> np.ndarray:
    """The unchanged-flag marks between scans: a bit per cell, set on the free cells of M whose
    buffers are settled (an unchanged flag would change nothing there, so no walk makes one)."""
    out = np.zeros((ref.size + 7) // 8, np.uint8)
    kernels().settled_marks(ref.reshape(-1), hist.reshape(-1), mask=buffer_mask(cfg),
                            full=settled_bound(cfg), out=out)
    return out


def full_marks(hist: np.ndarray, cfg: UpdaterConfig) -> np.ndarray:
    """The changed-flag marks between scans: a bit per cell, set on the cells whose buffers are
    full of changes (a changed flag would change nothing there but a count no rule reads, so
    no walk makes one: ``push_and_decide``)."""
    mask = np.uint16(buffer_mask(cfg))
    return np.packbits((hist.reshape(-1) & mask) == mask, bitorder="little")


def support_mode(cfg: UpdaterConfig) -> int:
    """The neighbour support the decision kernels apply: 0 none, 1 the paper's two states
    (free / occupied-or-unknown), 2 the same value of M (``support_exact_state``)."""
    if not cfg.neighbour_support:
        return 0
    return 2 if cfg.support_exact_state else 1


def push_flags(hist_flat: np.ndarray, seen_flat: np.ndarray, ref_flat: np.ndarray,
               n_changed: int, n_unchanged: int, cfg: UpdaterConfig, ch_marks: np.ndarray,
               un_marks: np.ndarray, ws: Workspace) -> int:
    """Shift the scan's flags into the cells' buffers, changed flags first:
    ``hist = ((hist << 1) | flag) & ((1 << N_b) - 1)``, and count them (flags a cell ever
    got, saturating: above the flags when ``count_shift`` says so, else in ``seen_flat``, at
    255). Only flagged cells are touched. Returns the count of
    entries written to ``ws.moved`` (cells whose decision inputs changed)."""
    ws.for_moved(n_changed + n_unchanged)
    return kernels().push_flags(hist_flat, seen_flat, ref_flat, changed=ws.changed[:n_changed],
                                unchanged=ws.unchanged[:n_unchanged], mask=buffer_mask(cfg),
                                threshold=cfg.threshold, few=cfg.unanimous_min,
                                ch_marks=ch_marks, un_marks=un_marks, out_moved=ws.moved,
                                shift=count_shift(cfg))


def decide(hist_flat: np.ndarray, seen_flat: np.ndarray, ref_flat: np.ndarray,
           decided: np.ndarray, n_moved: int, width: int, cfg: UpdaterConfig,
           ws: Workspace, stamp: np.ndarray) -> int:
    """The decision rule (n_c >= T; or, with ``unanimous_min``, every flag of a cell observed
    fewer than T times says changed; or n_c plus the 8-neighbours of the same state in M with
    n >= T reaches T) for the cells whose inputs changed this scan, each once (``stamp``:
    a bit plane, all clear, as the changed-flag marks are after the push). Returns the change
    of the number of changed cells."""
    return kernels().decide(hist_flat, seen_flat, ref_flat, decided, moved=ws.moved[:n_moved],
                            width=width, mask=buffer_mask(cfg), threshold=cfg.threshold,
                            few=cfg.unanimous_min, support=support_mode(cfg), stamp=stamp,
                            shift=count_shift(cfg))


def once_per_view(ws: Workspace, n: int, confirmed: np.ndarray, marks: np.ndarray
                  ) -> tuple[int, np.ndarray]:
    """The first n of ``ws.unchanged`` without the cells of ``confirmed`` (sorted: the cells
    confirmed since the last view), whose marks are cleared as the push would: (the count
    kept, ``confirmed`` with the kept cells added)."""
    cells = ws.unchanged[:n]
    again = np.isin(cells, confirmed, assume_unique=False)
    if again.any():
        dropped = cells[again]
        np.bitwise_and.at(marks, dropped >> 3,
                          (~np.left_shift(1, dropped & 7)).astype(np.uint8))
        cells = cells[~again]
        ws.unchanged[:cells.size] = cells
    return int(cells.size), np.union1d(confirmed, cells).astype(np.int32)


def push_and_decide(hist_flat: np.ndarray, seen_flat: np.ndarray, ref_flat: np.ndarray,
                    decided: np.ndarray, n_changed: int, n_unchanged: int, width: int,
                    cfg: UpdaterConfig, res: float, ch_marks: np.ndarray, un_marks: np.ndarray,
                    ws: Workspace) -> int:
    """``push_flags`` then ``decide`` in one kernel call (the changed-flag marks, after the push
    set on the cells whose buffers are full of changes alone, serve the decision as its
    stamps). Between scans the unchanged-flag marks stay set on the free cells whose buffers
    are settled (``settled_marks``), the changed-flag marks on the cells whose buffers are
    full of changes (``full_marks``). Returns the change of the number of changed cells."""
    ws.for_moved(n_changed + n_unchanged)
    st = ws.settings(cfg, res)
    return int(kernels().push_and_decide(
        hist_flat, seen_flat, ref_flat, decided, changed=ws.changed[:n_changed],
        unchanged=ws.unchanged[:n_unchanged], mask=st.mask, threshold=cfg.threshold,
        few=cfg.unanimous_min, support=st.support, width=width, ch_marks=ch_marks,
        un_marks=un_marks, moved=ws.moved, shift=st.shift, full=st.full))


def decide_all(hist_flat: np.ndarray, seen_flat: np.ndarray, ref_flat: np.ndarray, width: int,
               cfg: UpdaterConfig) -> tuple[np.ndarray, int]:
    """The decision rule over the whole map: (decided bits, count of changed cells)."""
    decided = np.zeros((ref_flat.size + 7) // 8, np.uint8)
    count = kernels().decide_all(hist_flat, seen_flat, ref_flat, decided, width=width,
                                 mask=buffer_mask(cfg), threshold=cfg.threshold,
                                 few=cfg.unanimous_min, support=support_mode(cfg),
                                 shift=count_shift(cfg))
    return decided, int(count)


# --- output and last check --------------------------------------------------------------------
def spread_freed(hist_flat: np.ndarray, seen_flat: np.ndarray, ref_flat: np.ndarray,
                 decided: np.ndarray, width: int, res: float, cfg: UpdaterConfig) -> np.ndarray:
    """Bits of the cells freed with the object they belong to (``cfg.spread_removed``): the
    occupied cells of M, connected through each other to one the rule freed, whose every
    flag says changed (one flag at least: a side of a box seen once or twice) and that lie
    beside no surface the scans still see, within structures of M's occupied cells of at most
    ``spread_max_area``. Empty bits when the rule is off."""
    spread = np.zeros_like(decided)
    if cfg.spread_removed:
        max_cells = int(math.floor(cfg.spread_max_area / res**2 + 1e-9))
        kernels().spread_freed(ref_flat, decided, hist_flat, seen_flat, width=width,
                               mask=buffer_mask(cfg), shift=count_shift(cfg),
                               max_cells=max_cells, spread=spread, done=np.zeros_like(decided),
                               big=np.zeros_like(decided))
    return spread


def keep_beside_standing(hist_flat: np.ndarray, seen_flat: np.ndarray, ref_flat: np.ndarray,
                         bits: np.ndarray, width: int, res: float, cfg: UpdaterConfig
                         ) -> np.ndarray:
    """``bits`` (the cells the output changes) without the occupied cells of M beside an
    occupied cell of M the output keeps, or beside an unknown cell of M that no flag reached,
    and, to a fixed point, those of them freed on fewer than T flags beside one kept so in a
    structure of M that stands (one the scans still see, or larger than ``spread_max_area``)
    (``cfg.free_with_neighbours``); ``bits`` itself when the rule is off."""
    if not cfg.free_with_neighbours:
        return bits
    out = bits.copy()
    max_cells = int(math.floor(cfg.spread_max_area / res**2 + 1e-9))
    kernels().keep_beside_standing(ref_flat, bits, hist_flat, seen_flat, width=width,
                                   mask=buffer_mask(cfg), shift=count_shift(cfg),
                                   threshold=cfg.threshold, max_cells=max_cells, out=out)
    return out


def close_outlines(ref: np.ndarray, decided: np.ndarray, enclosed: np.ndarray,
                   last_check: bool, drawn: np.ndarray | None = None,
                   seen_through: np.ndarray | None = None,
                   mask: int = 0xFFFF) -> tuple[np.ndarray, int]:
    """The output cells: M with the changed cells flipped (free <-> occupied, unknown seen
    through -> free) and, with ``last_check``, the outline of removed objects closed: each
    8-neighbour of a cell that became free that lies in an enclosed unknown region of M and is
    still unknown becomes occupied. The ``drawn`` cells (open unknown space hit often enough)
    become occupied. With ``seen_through`` (the buffers, their flags in the ``mask`` bits), a
    cell that holds a changed flag is not closed. Returns (cells, count closed by the last
    check)."""
    out = ref.copy()
    hist = np.zeros(0, np.uint16) if seen_through is None else seen_through.reshape(-1)
    closed = kernels().apply_changes(ref.reshape(-1), decided, enclosed, width=ref.shape[1],
                                     close=last_check, hist=hist, out=out.reshape(-1),
                                     mask=mask)
    if drawn is not None:
        kernels().apply_drawn(drawn, out.reshape(-1))
    return out, int(closed)


def enclosed_unknown(ref: np.ndarray, max_cells: int) -> tuple[np.ndarray, int]:
    """Bits of the cells of the enclosed unknown regions of M: 8-connected unknown regions that
    touch no map border and have at most ``max_cells`` cells (objects' interiors). Two unknown
    cells that touch only at a corner belong to one region, so a region counts as enclosed only
    if it is sealed against diagonal leaks too. Returns (bits, cells marked)."""
    k = kernels()
    n = k.unknown_runs(ref, np.zeros((0, 3), np.int32))
    runs = np.zeros((n, 3), np.int32)          # row, first col, last col
    k.unknown_runs(ref, runs)
    parent = np.zeros(n, np.int32)
    k.link_runs(runs, parent)
    bits = np.zeros((ref.size + 7) // 8, np.uint8)
    marked = k.mark_enclosed(runs, parent, ref.shape[0], ref.shape[1], max_cells, bits)
    return bits, int(marked)
