"""The Python side of the updater's steps (docs/algorithm.md): it sizes the workspace, works
out once what the kernels take from the configuration and the scan's layout, calls the
kernels and reads their results.

A scan past the gate is one kernel call, ``process_scan`` (``_scan.process_scan``: steps 1 to
4, the classifier, the lost check, both evaluators with the rules this project adds, the push
and the decision): each call from Python has a fixed cost, which a scan of a few hundred beams
feels. A scan the gate held back, with ``gate_confirm``, goes through ``classify_beams``,
``is_lost``, ``flag_unchanged_surfaces``, ``flag_hit_surfaces`` (``once_per_view``) and
``push_and_decide``. ``close_outlines`` builds the output map on demand (with ``spread_freed``
and ``keep_beside_standing``), ``enclosed_unknown`` prepares the last check once per
reference map, ``decide_all`` and ``decide_drawn`` decide a loaded state.

The kernels take the scan's layout and the configuration as the records of ``Layout`` and
``Settings`` and the arrays as the named tuples of ``updater._arguments``, where each field is
documented. Points are in grid units, (gx, gy) = ((x - ox) / res, (y - oy) / res); cells are
addressed by flat index ``row * width + col``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from gridmap import Scan

from ._arguments import DISTANCES, SETTINGS, Buffers, MapCells, Work, layout_record
from .config import UpdaterConfig
from .hit_tiles import HitTiles

NO_BITS = np.zeros(0, np.uint8)     # no enclosed regions: the classifier reads none


@functools.cache
def kernels():
    """The kernels module: numba is imported on first use, not with the package. Cached, as
    an import statement costs about as much as a small kernel's call."""
    from . import _kernels

    return _kernels


@dataclass
class Classified:
    """The classifier's result for one scan, for the steps of a held-back scan (views into the
    workspace: valid until the next scan). ``verdict`` holds a ``BeamVerdict`` per beam; the
    float arrays are NaN for invalid beams."""

    sensor: np.ndarray      # (gx, gy, yaw) [grid units, rad]
    ranges: np.ndarray      # [m], float64
    hits: np.ndarray        # (N, 2) hit points [grid units]
    pairing: np.ndarray     # D(r_i) [grid units]
    tol: np.ndarray         # tol(r_i) [grid units]
    skip: np.ndarray        # |p_i - p_th| [m]: what the removed-obstacle walk leaves out
    removed_reach: np.ndarray  # the removed-obstacle walk ends at this fraction of the way
    free_reach: np.ndarray  # the free walk ends at this fraction of the way to the hit
    verdict: np.ndarray     # int8
    valid: int              # valid beams
    raw_changes: int        # detected changes before the run filter
    changes: int            # detected changes kept by the run filter
    # per beam, for the lost check: the beam's own expected point, whether its virtual ray
    # found a blocking cell, the ray's direction, and whether the beam is a detected change
    own_expected: np.ndarray
    own_found: np.ndarray
    own_direction: np.ndarray
    change: np.ndarray
    wrap: bool              # the beams cover 360 degrees


class Workspace:
    """Scratch arrays reused from scan to scan, grown when a scan needs more; nothing here
    outlives a scan. Sizes follow the scan (beams, cells it reaches), never the map. The
    kernels take them as ``arrays()``, a ``_arguments.Work``."""

    # Per beam, one array per type with a row per quantity, in the order of
    # ``_arguments.Beams``' fields (each row is an attribute here too): each array is a field
    # of ``Work``, and a field costs a call about 0.1 µs.
    FLOATS = ("ranges", "pairing", "tol", "skip", "removed_reach", "free_reach", "unknown_reach",
              "free_skips")
    BOOLS = ("valid", "change", "keep", "into_unknown", "scratch")
    VERDICTS = ("verdict", "skipped_as_change")
    POINTS = ("hits", "measured")        # (n, 2) each
    RAYS = ("virtual", "expected")       # (m, 2) each, per virtual beam
    # each array of rows, by its attribute, and the names of its rows
    ROWS = (("floats", FLOATS), ("bools", BOOLS), ("verdicts", VERDICTS), ("points", POINTS),
            ("rays", RAYS))

    def __init__(self):
        self._beams = self._virtual = -1
        self.walk_room = 0                      # [cells] room for one walk's cells
        self._flags = self._moved = self._guarded = self._unknown_hits = -1
        self._own = None
        self._layout = self._layout_cfg = None
        self._settings = self._settings_cfg = None
        self._work = None
        # grown by the first scan that needs room
        self.floats = self.bools = self.verdicts = self.points = self.rays = self.found = None
        self.changed = self.unchanged = self.moved = self.guarded = np.zeros(0, np.int32)
        self.hits_unknown = np.zeros(0, np.int32)
        self.missing_tiles = np.zeros(0, np.int64)

    def arrays(self) -> Work:
        """The workspace as the kernels take it (made again after any array was grown)."""
        if self._work is None:
            self._work = Work(self.floats, self.bools, self.verdicts, self.points, self.rays,
                              self.found, self.guarded, self.hits_unknown, self.changed,
                              self.unchanged, self.moved, self.missing_tiles)
        return self._work

    def for_beams(self, n: int, m: int, walk: int) -> None:
        if n != self._beams:
            self._beams, self._work = n, None
            self.floats = np.zeros((len(self.FLOATS), n), np.float64)
            self.bools = np.zeros((len(self.BOOLS), n), np.bool_)
            self.verdicts = np.zeros((len(self.VERDICTS), n), np.int8)
            self.points = np.zeros((len(self.POINTS), n, 2), np.float64)
            for key, names in self.ROWS[:-1]:     # the rays: per virtual beam, below
                for name, row in zip(names, getattr(self, key)):
                    setattr(self, name, row)
            self.reach = self.removed_reach       # (its name in the distances' tests)
        if m != self._virtual:
            self._virtual, self._work = m, None
            self.rays = np.zeros((len(self.RAYS), m, 2), np.float64)
            self.virtual, self.expected = self.rays
            self.found = np.zeros(m, np.bool_)
            self._own = None
        self.walk_room = max(self.walk_room, walk)

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
            self._flags, self._work = capacity, None
            self.changed = np.zeros(capacity, np.int32)
            self.unchanged = np.zeros(capacity, np.int32)

    def for_unknown_hits(self, beams: int) -> None:
        if beams > self._unknown_hits:
            self._unknown_hits, self._work = beams, None
            self.hits_unknown = np.zeros(beams, np.int32)

    def for_missing_tiles(self, n: int) -> np.ndarray:
        """Room for the tiles of n hit cells (``push_hits``)."""
        if n > self.missing_tiles.shape[0]:
            self.missing_tiles, self._work = np.zeros(n, np.int64), None
        return self.missing_tiles

    def for_moved(self, capacity: int) -> None:
        if capacity > self._moved:
            self._moved, self._work = int(capacity * 1.25) + 64, None
            self.moved = np.zeros(self._moved, np.int32)

    def for_guarded(self, capacity: int) -> None:
        if capacity > self._guarded:
            self._guarded, self._work = int(capacity * 1.25) + 64, None
            self.guarded = np.zeros(self._guarded, np.int32)

    def layout(self, scan: Scan, cfg: UpdaterConfig, res: float) -> Layout:
        """The scan's ``Layout``, worked out again only when the beams' layout, the
        configuration (the same object) or the resolution changes; the per-beam arrays are
        sized for it."""
        key = (scan.ranges.size, scan.angle_min, scan.angle_increment, scan.range_min,
               scan.range_max, res)
        got = self._layout
        if got is None or got.key != key or self._layout_cfg is not cfg:
            record = layout_record(scan, cfg, res)
            n, ratio = key[0], cfg.virtual_to_measured_ratio
            self.for_beams(n, n * ratio, int(record[0]["walk_room"]))
            record["walk_room"] = self.walk_room
            got = Layout(key, record)
            self._layout, self._layout_cfg = got, cfg
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
        held = list(vars(self).values())
        for kept in (self._settings, self._layout):
            held += [kept.record] if kept is not None else []
        # the per-beam names are views of rows: counted in their arrays
        return sum(a.nbytes for a in held if isinstance(a, np.ndarray) and a.base is None)


@dataclass(frozen=True)
class Layout:
    """What the classifier takes from a scan's layout (its beams, angles and range limits), the
    configuration and the resolution: the same for every scan of a sensor, so worked out once
    (``Workspace.layout``)."""

    key: tuple          # (beams, angle_min, angle_increment, range_min, range_max, res)
    record: np.ndarray = field(compare=False)   # a one-element ``_arguments.LAYOUT`` array


@dataclass(frozen=True)
class Settings:
    """What the kernels take from the configuration and the resolution alone, worked out once
    per configuration (``Workspace.settings``): the ``SETTINGS`` record, and what the Python
    side reads of it."""

    res: float
    radius: float         # the seen-surface guard's radius [grid units]
    side: int             # the side of its square [cells]
    mask: int             # the buffers' rules: ``buffer_mask``, ``count_shift``,
    shift: int            # ``settled_bound`` and ``support_mode``
    full: int
    support: int
    record: np.ndarray = field(compare=False)   # a one-element ``_arguments.SETTINGS`` array

    @property
    def dist(self) -> np.ndarray:
        """The range-dependent distances' parameters, for ``kernels().beam_distances``."""
        return self.record[0]["distances"]

    @classmethod
    def of(cls, cfg: UpdaterConfig, res: float) -> Settings:
        radius = cfg.seen_surface_radius / res
        gaps = max(1, int(round(cfg.fill_gaps_clearance / res))) if cfg.fill_gaps else 0
        mask, shift, full, support = (buffer_mask(cfg), count_shift(cfg), settled_bound(cfg),
                                      support_mode(cfg))
        record = np.zeros(1, SETTINGS)
        record[0] = (res, [getattr(cfg, name) for name in DISTANCES],
                     cfg.virtual_to_measured_ratio, cfg.min_run, cfg.min_run_width / res,
                     cfg.n_skip, cfg.lost_fraction, cfg.walk_skipped_beams, radius,
                     unknown_guard(cfg, res), cfg.grow_into_unknown,
                     max(cfg.seen_surface_radius, res), cfg.grow_clear_of_surfaces, gaps,
                     cfg.fill_gaps_free_margin, cfg.confirm_hit_surfaces, mask, cfg.threshold, cfg.unanimous_min, support,
                     shift, full)
        return cls(res, radius, 2 * int(math.ceil(radius)) + 1, mask, shift, full, support,
                   record)


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
                   cfg: UpdaterConfig, ws: Workspace, clear: np.ndarray | None = None
                   ) -> Classified:
    """Valid beams, hit points, the per-beam distances, virtual beams cast once each, the
    windowed comparison with D(r), the run filter and the N_skip neighbourhood of the changes,
    in one kernel call (``run_classifier``). The window and the run filter wrap around the
    scan's ends only when the scan covers 360 degrees. A beam is invalid when its range is not
    finite, not above 0 (r = 0 is no hit), below the scan's range_min, or at or beyond
    min(max_range, the scan's range_max). ``clear``: M's ``clear_blocks`` (None: worked out
    here)."""
    clear = clear_blocks(ref) if clear is None else clear
    n = scan.beams
    ratio = cfg.virtual_to_measured_ratio
    lay, st = ws.layout(scan, cfg, res), ws.settings(cfg, res)
    n_valid, bound, raw, kept = kernels().run_classifier(
        scan.ranges, sensor, lay.record, st.record, MapCells(ref, clear, NO_BITS), ws.arrays())
    # No evaluator can flag more cells than the bound or the map holds; the n more leave room
    # for an unchanged flag at each beam's hit cell.
    ws.for_flags(min(bound, ref.size) + n)
    expected, found, direction = ws.own(ratio, n)
    return Classified(sensor, ws.ranges, ws.hits, ws.pairing, ws.tol, ws.skip, ws.removed_reach,
                      ws.free_reach, ws.verdict, n_valid, raw, kept, expected, found,
                      direction, ws.change, bool(lay.record[0]["even_wrap"]))


def is_lost(beams: Classified, cfg: UpdaterConfig, ref: np.ndarray) -> bool:
    """More than ``lost_fraction`` of the valid beams disagree with the map (counted before the
    run filter): the pose is probably wrong, so the scan is dropped (``scan_is_lost``, whose
    rule ``process_scan`` applies too)."""
    return bool(kernels().scan_is_lost(ref, beams.own_expected, beams.own_direction,
                                       beams.own_found, beams.ranges, beams.change, beams.valid,
                                       beams.raw_changes, cfg.lost_fraction))


def unknown_guard(cfg: UpdaterConfig, res: float) -> float:
    """The seen-surface guard's radius [grid units] for open unknown cells: the whole radius
    with the paper's rules; growing into the unknown, one cell at most. There the cells a scan
    hits keep out of its walks anyway (``list_unknown_hits``), and a guard of 1.5 cells kept
    the free space from ever reaching a wall M had not seen (on the Intel log more of the
    well-observed cells stayed unknown than with one cell); none at all let rays grazing a
    rack's corner that M had as unknown free it under 5 cm of pose error."""
    radius = cfg.seen_surface_radius / res
    return min(radius, 1.0) if cfg.grow_into_unknown else radius


# --- a held-back scan's unchanged flags -------------------------------------------------------
def flag_unchanged_surfaces(ref: np.ndarray, beams: Classified, marks: np.ndarray,
                            ws: Workspace) -> int:
    """The unchanged flags of the occupied-or-unknown cells of M among the hit cell and its
    4-neighbours of each UNCHANGED beam (``_flags.flag_occupied_unchanged``), into
    ``ws.unchanged`` (each cell once, ``marks``). Returns the count."""
    return kernels().flag_occupied_unchanged(ref, beams.hits, beams.verdict, marks,
                                             ws.unchanged, 0)


def flag_hit_surfaces(ref: np.ndarray, beams: Classified, cfg: UpdaterConfig, marks: np.ndarray,
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


# --- a scan past the gate in one call -------------------------------------------------------------
def process_scan(scan: Scan, sensor: np.ndarray, res: float, cfg: UpdaterConfig, ws: Workspace,
                 cells: MapCells, state: Buffers, tiles: HitTiles
                 ) -> tuple[int, int, int, tuple[int, int, int, int, int] | None]:
    """Steps 1 to 4 for a scan past the gate, in one kernel call (``_scan.process_scan``):
    the classifier, the lost check, the changed and unchanged flags with the rules this
    project adds (the seen-surface guard, ``fill_gaps``, the hits that confirm M's surfaces,
    the growth into the unknown), the push and the decision, and the hit buffers. The call is
    made again when the workspace lacks room for the scan's flags (it then flags nothing);
    the pushes are left to calls of their own when it lacks room for the flags' entries, or a
    hit cell its tile. Returns (valid beams, detected changes, changes kept by the run filter,
    then None for a lost scan, else (changed flags, new-obstacle and fill_gaps flags,
    unchanged flags, the change of the number of changed cells, that of the drawn cells));
    the classifier's arrays stay in ``ws``."""
    k, lay, st, n = kernels(), ws.layout(scan, cfg, res), ws.settings(cfg, res), scan.beams
    ws.for_guarded(min(n * st.side * st.side, cells.ref.size) if st.radius > 0 else 0)
    ws.for_unknown_hits(n)
    ws.for_missing_tiles(n)
    while True:
        got = k.process_scan(scan.ranges, sensor, lay.record, st.record, cells, state,
                             ws.arrays())
        if got[4] != k.NEEDS_ROOM:
            break
        ws.for_flags(got[3])
    n_valid, raw, kept, _, n_ch, n_new, n_gaps, n_un, n_hits, d_changed, d_drawn, n_missing = got
    if n_ch < 0:
        return n_valid, raw, kept, None
    if n_missing < 0:           # no room for the flags' entries: the pushes, one by one
        d_changed = push_and_decide(state, cells.ref, n_ch, n_un, cfg, res, ws)
    if n_missing != 0 and cfg.grow_into_unknown:
        d_drawn = push_hits(tiles, cells.ref, cells.enclosed, n_hits, n_ch, cfg, res,
                            state.hit_marks, state.drawn, ws)
    return n_valid, raw, kept, (n_ch, n_new + n_gaps, n_un, d_changed, d_drawn)


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


def push_and_decide(state: Buffers, ref: np.ndarray, n_changed: int, n_unchanged: int,
                    cfg: UpdaterConfig, res: float, ws: Workspace) -> int:
    """The first ``n_changed`` of ``ws.changed`` and ``n_unchanged`` of ``ws.unchanged`` into
    the buffers, then the decision, in one kernel call (``_decide.push_and_decide``: the
    changed-flag marks, after the push set on the cells whose buffers are full of changes
    alone, serve the decision as its stamps). Between scans the unchanged-flag marks stay set
    on the free cells whose buffers are settled (``settled_marks``), the changed-flag marks on
    the cells whose buffers are full of changes (``full_marks``). Returns the change of the
    number of changed cells."""
    ws.for_moved(n_changed + n_unchanged)
    return int(kernels().push_and_decide(state, ref.reshape(-1), ref.shape[1],
                                         ws.changed[:n_changed], ws.unchanged[:n_unchanged],
                                         ws.moved, ws.settings(cfg, res).record))


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


def decide_all(hist_flat: np.ndarray, seen_flat: np.ndarray, ref_flat: np.ndarray, width: int,
               cfg: UpdaterConfig) -> tuple[np.ndarray, int]:
    """The decision rule over the whole map: (decided bits, count of changed cells)."""
    decided = np.zeros((ref_flat.size + 7) // 8, np.uint8)
    count = kernels().decide_all(hist_flat, seen_flat, ref_flat, decided, width=width,
                                 mask=buffer_mask(cfg), threshold=cfg.threshold,
                                 few=cfg.unanimous_min, support=support_mode(cfg),
                                 shift=count_shift(cfg))
    return decided, int(count)


def decide_drawn(tiles: HitTiles, ref: np.ndarray, enclosed: np.ndarray, cfg: UpdaterConfig,
                 drawn: np.ndarray) -> int:
    """The drawn bits of every hit buffer (on loading a saved state). Returns the count."""
    return int(kernels().decide_drawn(tiles.directory, tiles.pool, ref.shape[0], ref.shape[1],
                                      ref.reshape(-1), enclosed,
                                      mask=np.uint16(buffer_mask(cfg)), threshold=cfg.threshold,
                                      few=cfg.unanimous_min, drawn=drawn))


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
