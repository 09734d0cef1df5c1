"""Edited-world cases: a real recording and its map, with the world edited so that the truth
of every change is known exactly, while the noise, the poses, the scan rate and the geometry
stay the recording's own.

- a **removed** object is a box drawn into the map (outline cells occupied, interior unknown,
  as a SLAM map shows an object) where the real scans see free floor: the update must free it;
- an **added** object is a box cut into the real scans where the map has free floor: every beam
  that crosses the box ends on its boundary (when that is nearer than what the laser measured,
  or the laser measured no return): the update must draw its seen outline;
- a **moved** object is a removed box at A and an added box of the same size at B;
- **people** are discs walking the free space, cut into the scans at each scan's time; they are
  never part of the truth, only a record of where false changes could come from.

``make_case`` places all this (seeded, so a seed gives the same case byte for byte);
:mod:`evaluation.case_folder` writes the case folder (``stale.yaml`` + ``stale.pgm``,
``log.clf``, ``truth.npz``, ``case.yaml``) and scores an updated map against it, and
:mod:`evaluation.edited_geometry` holds the geometry of boxes and discs against beams. Geometry is
vectorised over the beams of a scan (or of the whole log). Of this project it imports only
``gridmap``: observations are anything with the attributes of ``robotlogs.Observation``
(``time``, ``scan``, ``mount``, ``odom``, ``recorded``, ``sensor``), as
``robotlogs.log_observations`` gives them. The user's guide is docs/edited_world.md.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace

import numpy as np
from tqdm import tqdm

from gridmap import FREE, OCCUPIED, UNKNOWN, MapUpdatingError, OccupancyGrid, Pose2D
from gridmap.distance import distance_to_occupied

from .edited_geometry import Box, box_entry, box_params, cut_in, disc_entry, edit_scans, ray_entry
from .scores import ObservationCounter

BOX_SIDE = (0.4, 1.2)         # [m] a box's sides are drawn from this range
CLEARANCE = 0.3               # [m] of free map around a box, and between boxes
PATH_MARGIN = 0.6             # [m] a box keeps this far from every laser position
MIN_BEAMS = 3                 # beams a scan must cross a box with to count as seeing it
TRIES = 4000                  # random candidates per box before giving up on it
VIEW_TRIES = 300              # candidates per box whose views are counted (the costly check)
PAIR_TRIES = 5                # places A tried for a moved object (each with its tries at B)
PERSON_RADIUS = (0.2, 0.25)   # [m]
PERSON_SPEED = (0.5, 1.3)     # [m/s]
PERSON_PAUSE = (2.0, 6.0)     # [s] standing still ...
PAUSE_CHANCE = 0.3            # ... this often after a leg
PERSON_CLEARANCE = 0.1        # [m] between a person's disc and walls or boxes
PERSON_LEG = (1.0, 12.0)      # [m] length of a straight leg of a walk
PEOPLE_NEAR_PATH = 8.0        # [m] people walk where the laser passes within this distance
MAX_COUNT = 100               # boxes or people of one kind a case may ask for
# The CARMEN reader's FLASER geometry and limits (robotlogs/carmen.py; the tests check that
# these agree): a scan of this geometry is written as FLASER, any other as ROBOTLASER1.
FLASER_NO_RETURN = 81.83
CARMEN_RANGE_MIN = 0.01
CASE_FILES = ("stale.yaml", "stale.pgm", "log.clf", "truth.npz", "case.yaml")
TRUTH_MASKS = ("removed_outline", "removed_seen", "removed_interior", "added_outline", "added_all",
               "people")
# [m] the updater's removed-obstacle walk stops this short of a return (removed_skip_min): a
# removed box's outline cell counts as seen when a beam passes through it that far before its
# return
WALK_SKIP = 0.15
# Scores are also given on the outline cells seen by at least this many scans: the fewest on
# which any rule of the updater decides (its unanimous rule; the paper's threshold is 7)
FEW_VIEWS = 3
MAX_WALK = 100.0       # [m] longer than any lidar's range
ZIP_TIME = (1980, 1, 1, 0, 0, 0)   # fixed member times: the same case is the same bytes


class CaseError(MapUpdatingError, ValueError):
    """A case that cannot be made, written or scored; the message names what is wrong."""


# --- the scans of a log ------------------------------------------------------------------------

def laser_pose(obs) -> Pose2D | None:
    """The laser's pose in the map frame the log records for an observation, or None."""
    pose = obs.sensor if getattr(obs, "sensor", None) is not None else (
        None if obs.recorded is None else obs.recorded.compose(obs.mount))
    return pose if pose is not None and pose.is_finite() else None


def scan_times(times) -> tuple[np.ndarray, str | None]:
    """The times people move by: the scans' own, or, when they are broken (not finite, all
    equal, going backwards), scan order times a nominal period (the median positive interval,
    else 1 s), with a note saying so."""
    t = np.asarray(times, np.float64)
    d = np.diff(t)
    if t.size < 2 or (np.isfinite(t).all() and (d >= 0).all() and t[-1] > t[0]):
        return (t if np.isfinite(t).all() else np.zeros_like(t)), None
    good = d[np.isfinite(d) & (d > 0)]
    period = float(np.median(good)) if good.size else 1.0
    return np.arange(t.size) * period, (f"the log's times are broken (not finite, all equal or "
                                        f"going backwards): people move by scan order, "
                                        f"{period:g} s a scan")


@dataclass(frozen=True, eq=False)
class _Beams:
    """Every beam of the log, flat: its scan, origin, direction, reading and limits."""

    scan: np.ndarray
    ox: np.ndarray
    oy: np.ndarray
    ca: np.ndarray
    sa: np.ndarray
    ranges: np.ndarray
    range_min: np.ndarray
    range_max: np.ndarray
    scans: int

    @staticmethod
    def of(placed) -> _Beams:
        n = np.array([s.beams for s, _ in placed])
        rep = lambda v: np.repeat(np.asarray(v, np.float64), n)  # noqa: E731
        angles = np.concatenate([s.angles() + p.theta for s, p in placed])
        return _Beams(np.repeat(np.arange(len(placed)), n),
                      rep([p.x for _, p in placed]), rep([p.y for _, p in placed]),
                      np.cos(angles), np.sin(angles),
                      np.concatenate([s.ranges.astype(np.float64) for s, _ in placed]),
                      rep([s.range_min for s, _ in placed]), rep([s.range_max for s, _ in placed]),
                      len(placed))

    def entry(self, box: Box, idx=None) -> tuple[np.ndarray, np.ndarray]:
        """(beams, their entry distances into ``box``) among ``idx`` (default: the beams whose
        line passes the box's bounding circle ahead of the laser; no other can cross it)."""
        if idx is None:
            reach = math.hypot(box.w, box.h) / 2
            vx, vy = box.cx - self.ox, box.cy - self.oy
            idx = np.flatnonzero((np.abs(vx * self.sa - vy * self.ca) <= reach)
                                 & (vx * self.ca + vy * self.sa >= -reach))
        return idx, ray_entry(self.ox[idx], self.oy[idx], self.ca[idx], self.sa[idx],
                           box_params([box]))[0]

    def seeing(self, kind: str, idx, t, ranges: np.ndarray) -> np.ndarray:
        """Which of the beams ``idx`` (entries ``t``) see a box: for an added box those that end
        on it (or would), for a removed one those passing into its area."""
        r = ranges[idx]
        with np.errstate(invalid="ignore"):
            if kind in ("added", "moved_to"):   # (<=: the ranges may end on it already)
                return (t <= r) & (t >= self.range_min[idx]) & (t < self.range_max[idx])
            # a removed box must stand where the scans see floor: a return beyond it, not
            # "no return" (a window, open space: nothing says the floor there is empty)
            return (t < r) & (r < self.range_max[idx])

    def counts(self, idx) -> np.ndarray:
        """Beams per scan among ``idx``."""
        return np.bincount(self.scan[idx], minlength=self.scans)


def _views(counts: np.ndarray) -> int:
    """Scans that see a box: those with ``MIN_BEAMS`` beams on it or more."""
    return int(np.count_nonzero(counts >= MIN_BEAMS))


# --- placing boxes -----------------------------------------------------------------------------

@dataclass(frozen=True)
class PlacedBox:
    """A box of the case: its kind (removed, added, moved_from, moved_to), the scans of the
    edited log that see it (``MIN_BEAMS`` beams or more) and, for a moved object, its pair."""

    kind: str
    box: Box
    views: int = 0
    pair: int | None = None

    @property
    def added(self) -> bool:
        return self.kind in ("added", "moved_to")


class _Placer:
    """Random boxes on free floor, clear of the path and of each other, seen by enough scans.
    ``ranges`` are the log's readings with the added boxes placed so far cut in, so a box is
    seen through the edited scans, and no added box may hide one placed before from view."""

    def __init__(self, grid: OccupancyGrid, placed, rng, min_views: int):
        self.grid, self.rng, self.min_views = grid, rng, min_views
        self.free = grid.data == FREE
        self.free_cells = np.flatnonzero(self.free)
        self.lasers = np.array([[p.x, p.y] for _, p in placed], np.float64)
        self.beams = _Beams.of(placed)
        self.ranges = self.beams.ranges.copy()
        self.taken = np.zeros(grid.shape, bool)
        self.boxes: list[PlacedBox] = []
        self.counts: list[np.ndarray] = []     # beams per scan on each box placed

    def candidate(self, size=None) -> Box:
        k = int(self.free_cells[self.rng.integers(self.free_cells.size)])
        x, y = self.grid.cell_to_world(k // self.grid.width, k % self.grid.width)
        jx, jy = self.rng.uniform(-0.5, 0.5, 2) * self.grid.resolution
        w, h = size if size is not None else self.rng.uniform(*BOX_SIDE, 2)
        yaw = self.rng.uniform(0.0, math.pi)
        return Box(round(float(x + jx), 3), round(float(y + jy), 3), round(float(w), 3),
                   round(float(h), 3), round(float(yaw), 4))

    def fits(self, box: Box, taken: np.ndarray) -> bool:
        """Free map under the box and ``CLEARANCE`` around it, no other box there, and every
        laser position ``PATH_MARGIN`` away."""
        r0, c0, around, clipped = box.window(self.grid, CLEARANCE)
        if clipped:
            return False
        h, w = around.shape
        if not self.free[r0:r0 + h, c0:c0 + w][around].all() or \
                taken[r0:r0 + h, c0:c0 + w][around].any():
            return False
        return float(box.distance(self.lasers[:, 0], self.lasers[:, 1]).min()) >= PATH_MARGIN

    def seen(self, box: Box, kind: str):
        """(ranges with ``box`` cut in, its beams per scan, those of the boxes placed before)
        when enough scans see it and it hides no box placed before from view, else None."""
        beams = self.beams
        idx, t = beams.entry(box)
        on = beams.seeing(kind, idx, t, self.ranges)
        counts = beams.counts(idx[on])
        if _views(counts) < self.min_views:
            return None
        if kind not in ("added", "moved_to"):
            return self.ranges, counts, self.counts
        cut = idx[on]
        ranges = self.ranges.copy()
        ranges[cut] = t[on]
        others = []
        for b, before in zip(self.boxes, self.counts):
            jdx, tb = beams.entry(b.box, cut)         # only the cut beams can change its view
            was, now = beams.seeing(b.kind, jdx, tb, self.ranges), beams.seeing(b.kind, jdx, tb,
                                                                                ranges)
            after = before - beams.counts(jdx[was & ~now]) + beams.counts(jdx[now & ~was])
            if _views(after) < self.min_views:
                return None
            others.append(after)
        return ranges, counts, others

    def place(self, kind: str, size=None, taken=None, view_tries: int = VIEW_TRIES):
        """(box, its state for ``accept``) of the first random candidate that fits, or
        (None, None)."""
        taken = self.taken if taken is None else taken
        for _ in range(TRIES):
            box = self.candidate(size)
            if not self.fits(box, taken):
                continue
            state = self.seen(box, kind)
            if state is not None:
                return box, state
            view_tries -= 1
            if view_tries <= 0:
                break
        return None, None

    def accept(self, kind: str, box: Box, state, pair=None) -> None:
        ranges, counts, others = state
        self.boxes.append(PlacedBox(kind, box, pair=pair))
        self.ranges, self.counts = ranges, [*others, counts]
        outline, interior = box.masks(self.grid)
        self.taken |= outline | interior

    def place_pair(self, pair: int) -> bool:
        """A moved object: a removed box at A and an added one of its size at B."""
        for _ in range(PAIR_TRIES):
            a, state_a = self.place("moved_from")
            if a is None:
                return False
            outline, interior = a.masks(self.grid)
            self.boxes.append(PlacedBox("moved_from", a, pair=pair))   # B must not hide A
            self.counts.append(state_a[1])
            b, state_b = self.place("moved_to", (a.w, a.h), self.taken | outline | interior,
                                    VIEW_TRIES // 3)
            self.boxes.pop()
            self.counts.pop()
            if b is not None:
                self.accept("moved_from", a, state_a, pair)
                self.accept("moved_to", b, state_b, pair)
                return True
        return False

    def place_all(self, removed: int, added: int, moved: int, bar) -> None:
        """Moved objects first (they need two places), then removed and added boxes; once a
        box of a kind finds no place, no more of that kind are tried (the floor only fills)."""
        for k in range(moved):
            bar.update(1)
            if not self.place_pair(k):
                break
        for kind, count in (("removed", removed), ("added", added)):
            for _ in range(count):
                bar.update(1)
                box, state = self.place(kind)
                if box is None:
                    break
                self.accept(kind, box, state)


# --- people ------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Person:
    """A disc walking straight legs between free points, standing still now and then: its
    positions at ``times`` (knots, increasing), linear in between."""

    radius: float
    times: np.ndarray
    xy: np.ndarray

    def at(self, t) -> tuple[np.ndarray, np.ndarray]:
        return (np.interp(t, self.times, self.xy[:, 0]), np.interp(t, self.times, self.xy[:, 1]))


class _Walker:
    """Walks on the cells where a person's disc keeps clear of walls, unknown space and boxes,
    near where the laser passes (where a person can be seen)."""

    def __init__(self, grid: OccupancyGrid, taken: np.ndarray, lasers: np.ndarray, rng):
        self.grid, self.rng = grid, rng
        self.walkable = np.zeros(grid.shape, bool)
        self.starts = np.zeros(0, np.int64)
        rows, cols = np.nonzero(grid.data == FREE)
        if rows.size == 0:
            return
        # distance fields over the box around the free cells only (a map is mostly unknown)
        r0, r1, c0, c1 = rows.min() - 1, rows.max() + 2, cols.min() - 1, cols.max() + 2
        r0, c0 = max(r0, 0), max(c0, 0)
        window = grid.data[r0:r1, c0:c1]
        frame = OccupancyGrid(np.full(window.shape, FREE, np.int8), grid.resolution,
                              (grid.origin[0] + c0 * grid.resolution,
                               grid.origin[1] + r0 * grid.resolution))
        blocked = (window != FREE) | taken[r0:r1, c0:c1]
        room = distance_to_occupied(frame.with_data(np.where(blocked, OCCUPIED, FREE)
                                                    .astype(np.int8)))
        walkable = room >= PERSON_RADIUS[1] + PERSON_CLEARANCE + grid.resolution
        r, c = frame.world_to_cell(lasers[:, 0], lasers[:, 1])
        inside = frame.contains(r, c)
        if inside.any():
            path = np.full(window.shape, FREE, np.int8)
            path[r[inside], c[inside]] = OCCUPIED
            walkable &= distance_to_occupied(frame.with_data(path),
                                             PEOPLE_NEAR_PATH + 1.0) <= PEOPLE_NEAR_PATH
        self.walkable[r0:r1, c0:c1] = walkable
        self.starts = np.flatnonzero(self.walkable)

    def ok(self, x, y) -> np.ndarray:
        r, c = self.grid.world_to_cell(x, y)
        inside = self.grid.contains(r, c)
        out = np.zeros(np.shape(r), bool)
        out[inside] = self.walkable[r[inside], c[inside]]
        return out

    def leg(self, x: float, y: float):
        """The end of a straight walkable leg from (x, y), or None."""
        for _ in range(30):
            a, length = self.rng.uniform(0.0, 2 * math.pi), self.rng.uniform(*PERSON_LEG)
            s = np.linspace(0.0, length, int(length / (0.5 * self.grid.resolution)) + 2)
            if self.ok(x + s * math.cos(a), y + s * math.sin(a)).all():
                return x + length * math.cos(a), y + length * math.sin(a)
        return None

    def walk(self, t0: float, t1: float) -> Person:
        rng = self.rng
        radius = float(rng.uniform(*PERSON_RADIUS))
        k = int(self.starts[rng.integers(self.starts.size)])
        x, y = (float(v) for v in self.grid.cell_to_world(k // self.grid.width,
                                                          k % self.grid.width))
        times, xy, t = [t0], [(x, y)], t0
        while t <= t1 and len(times) < 1_000_000:
            end = None if rng.random() < PAUSE_CHANCE else self.leg(x, y)
            if end is None:
                t += rng.uniform(*PERSON_PAUSE)
            else:
                t += math.hypot(end[0] - x, end[1] - y) / rng.uniform(*PERSON_SPEED)
                x, y = end
            times.append(t)
            xy.append((x, y))
        return Person(radius, np.array(times), np.array(xy, np.float64))


def _people(grid: OccupancyGrid, placer: _Placer, count: int, times: np.ndarray, rng):
    """``count`` walking people over the log's times, and a note when none can walk."""
    if count == 0:
        return (), None
    walker = _Walker(grid, placer.taken, placer.lasers, rng)
    if walker.starts.size == 0:
        return (), "no free space near the path for people to walk in"
    t0, t1 = float(times.min()), float(times.max())
    return tuple(walker.walk(t0, t1) for _ in range(count)), None


def people_mask(grid: OccupancyGrid, people: Sequence[Person]) -> np.ndarray:
    """The cells whose centres any person's disc covered, anywhere along the walk."""
    mask = np.zeros(grid.shape, bool)
    res = grid.resolution
    for p in people:
        step = np.hypot(*np.diff(p.xy, axis=0).T)
        s = np.r_[0.0, np.cumsum(step)]
        keep = np.r_[True, step > 0]
        samples = np.r_[np.arange(0.0, s[-1], 0.5 * res), s[-1]]
        x = np.interp(samples, s[keep], p.xy[keep, 0])
        y = np.interp(samples, s[keep], p.xy[keep, 1])
        k = int(math.ceil(p.radius / res)) + 1
        dr, dc = (v.ravel() for v in np.mgrid[-k:k + 1, -k:k + 1])
        for i in range(0, samples.size, 4096):
            r0, c0 = grid.world_to_cell(x[i:i + 4096], y[i:i + 4096])
            rows, cols = r0[:, None] + dr, c0[:, None] + dc
            cx, cy = grid.cell_to_world(rows, cols)
            cover = (np.hypot(cx - x[i:i + 4096, None], cy - y[i:i + 4096, None]) <= p.radius) \
                & grid.contains(rows, cols)
            mask[rows[cover], cols[cover]] = True
    return mask


# --- the case ----------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Case:
    """An edited-world case in memory: the user's map (``reference``), the stale map with the
    removed boxes drawn in, the boxes and people, the scans used (observations with their laser
    poses) and their edited ranges, the truth masks and notes (shortfalls, broken times)."""

    seed: int
    min_views: int
    asked: dict
    reference: OccupancyGrid
    stale: OccupancyGrid
    boxes: tuple[PlacedBox, ...]
    people: tuple[Person, ...]
    observations: tuple
    sensors: tuple[Pose2D, ...]
    ranges: tuple[np.ndarray, ...]
    truth: dict
    notes: tuple[str, ...] = ()
    dropped: int = 0

    def placed(self) -> dict:
        """How many of each were placed, as ``asked`` counts them (a moved object once)."""
        kinds = [b.kind for b in self.boxes]
        return {"removed": kinds.count("removed"), "added": kinds.count("added"),
                "moved": kinds.count("moved_to"), "people": len(self.people)}


def _check_counts(seed, removed, added, moved, people, min_views) -> None:
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or \
            not 0 <= seed < 2 ** 63:
        raise CaseError(f"the seed must be a whole number from 0 to 2^63 - 1, got {seed!r}")
    for name, v in (("removed", removed), ("added", added), ("moved", moved),
                    ("people", people)):
        if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or not 0 <= v <= MAX_COUNT:
            raise CaseError(f"{name} must be a whole number from 0 to {MAX_COUNT}, got {v!r}")
    if not isinstance(min_views, (int, np.integer)) or isinstance(min_views, bool) or \
            not 1 <= min_views <= 100_000:
        raise CaseError(f"min_views must be a whole number of scans >= 1, got {min_views!r}")
    if removed + added + moved + people == 0:
        raise CaseError("a case needs at least one removed, added or moved box or a person")


def _bar(progress: bool, **kw):
    return tqdm(disable=not progress, delay=1.0, leave=False, dynamic_ncols=True, **kw)


def make_case(grid: OccupancyGrid, observations: Iterable, seed: int, removed: int = 4,
              added: int = 4, moved: int = 0, people: int = 0, min_views: int = 5, *,
              progress: bool = False) -> Case:
    """Place the boxes and people of a case on ``grid`` (the user's map) and the scans of
    ``observations`` (those with a recorded laser pose), all random draws from
    ``numpy.random.default_rng(seed)``. Fewer boxes than asked is noted in the case; none at
    all (when some were asked) is a ``CaseError``."""
    _check_counts(seed, removed, added, moved, people, min_views)
    observations = list(observations)
    used = [(o, p) for o in observations if (p := laser_pose(o)) is not None]
    if not used:
        raise CaseError(f"none of the log's {len(observations)} scans has a recorded laser pose: "
                        "a case needs a log with corrected poses or a recorded localisation")
    if not (grid.data == FREE).any():
        raise CaseError("the map has no free cell to place anything on")
    rng = np.random.default_rng(seed)
    placer = _Placer(grid, [(o.scan, p) for o, p in used], rng, min_views)
    with _bar(progress, total=moved + removed + added, desc="placing boxes", unit="box") as bar:
        placer.place_all(removed, added, moved, bar)
    asked = {"removed": removed, "added": added, "moved": moved, "people": people}
    if removed + added + moved and not placer.boxes:
        raise CaseError(_shortfall_text(asked, {"removed": 0, "added": 0, "moved": 0},
                                        min_views, none=True))
    times, time_note = scan_times([o.time for o, _ in used])
    walkers, people_note = _people(grid, placer, people, times, rng)
    ranges, views, ends, through = _edited_scans(grid, used, placer.boxes, walkers, times,
                                                 progress)
    boxes = tuple(PlacedBox(b.kind, b.box, int(v), b.pair) for b, v in zip(placer.boxes, views))
    truth = _truth(grid, boxes, walkers, ends, through)
    stale = grid.data.copy()
    stale[truth["removed_outline"]] = OCCUPIED
    stale[truth["removed_interior"]] = UNKNOWN
    case = Case(int(seed), int(min_views), asked, grid, grid.with_data(stale), boxes, walkers,
                tuple(o for o, _ in used), tuple(p for _, p in used), tuple(ranges), truth,
                dropped=len(observations) - len(used))
    notes = [n for n in (_shortfall_text(asked, case.placed(), min_views), time_note,
                         people_note) if n]
    notes += [f"{b.kind} box {i + 1} is seen by only {b.views} scans once people are cut in"
              for i, b in enumerate(boxes) if b.views < min_views]
    return replace(case, notes=tuple(notes))


def _shortfall_text(asked: dict, placed: dict, min_views: int, none: bool = False) -> str | None:
    short = [f"{placed[k]} of {asked[k]} {k}" for k in ("removed", "added", "moved")
             if placed[k] < asked[k]]
    if not short:
        return None
    rule = (f"free floor with {CLEARANCE:g} m free around, {PATH_MARGIN:g} m from the path, "
            f"seen by >= {min_views} scans with >= {MIN_BEAMS} beams each")
    if none:
        return f"no box fits this map and log ({rule})"
    return f"only {', '.join(short)} boxes fit ({rule})"


def _edited_scans(grid: OccupancyGrid, used, boxes: Sequence[PlacedBox], people, times,
                  progress: bool):
    """Every scan with the added boxes and the people cut in: (ranges, views of each box,
    end points (x, y) of the beams that end on an added box, and per cell the scans whose
    beams pass through it on their way to a return beyond a removed box)."""
    added = box_params([b.box for b in boxes if b.added])
    removed = box_params([b.box for b in boxes if not b.added])
    seen_added, seen_removed = np.zeros(len(added), int), np.zeros(len(removed), int)
    through = ObservationCounter(grid, max_range=MAX_WALK)
    out, ends = [], []
    for i, (obs, pose) in enumerate(_bar(progress, iterable=used, desc="editing scans",
                                         unit="scan")):
        discs = [(*p.at(times[i]), p.radius) for p in people]
        ranges, _, box_t, which, on_box = cut_in(obs.scan, pose, added, discs)
        out.append(ranges)
        angles = obs.scan.angles() + pose.theta
        seen_added += np.bincount(which[on_box], minlength=len(added)) >= MIN_BEAMS
        if len(removed):
            t = box_entry(pose.x, pose.y, angles, removed)
            r = ranges.astype(np.float64)
            with np.errstate(invalid="ignore"):
                passes = (t < r) & (r < obs.scan.range_max)
            seen_removed += passes.sum(axis=1) >= MIN_BEAMS
            # every return's walk, stopped short of it: a beam may cross an outline cell's
            # corner without entering the box
            with np.errstate(invalid="ignore"):
                ret = np.isfinite(r) & (r < obs.scan.range_max) & (r > WALK_SKIP)
            through.add_scan(pose, r[ret] - WALK_SKIP, angles[ret] - pose.theta)
        a, t = angles[on_box], box_t[on_box]
        ends.append(np.c_[pose.x + t * np.cos(a), pose.y + t * np.sin(a)])
    views, ia, ir = [], iter(seen_added), iter(seen_removed)
    for b in boxes:
        views.append(next(ia) if b.added else next(ir))
    return out, views, ends, through.counts


def _truth(grid: OccupancyGrid, boxes: Sequence[PlacedBox], people, ends,
           through: np.ndarray) -> dict:
    """The truth masks on the map's grid (``TRUTH_MASKS``), the scans that saw each outline
    cell (``removed_views``: beams passed through it to a return beyond; ``added_views``:
    beams ended on it) and the reference map's cells. ``ends``: per scan, the end points of
    its beams on added boxes; ``through``: per cell, the scans whose beams pass through it."""
    masks = {k: np.zeros(grid.shape, bool) for k in TRUTH_MASKS}
    for b in boxes:
        outline, interior = b.box.masks(grid)
        if b.added:
            masks["added_all"] |= outline
        else:
            masks["removed_outline"] |= outline
            masks["removed_interior"] |= interior
    added_views = hit_counts(grid, masks["added_all"], ends)
    masks["added_outline"] = added_views > 0
    masks["removed_seen"] = masks["removed_outline"] & (through > 0)
    views = {"removed_views": np.where(masks["removed_outline"], through, 0).astype(np.uint16),
             "added_views": np.minimum(added_views, 65535).astype(np.uint16)}
    masks["people"] = people_mask(grid, people)
    return {**masks, **views, "reference": grid.data.copy(),
            "resolution": np.float64(grid.resolution), "origin": np.array(grid.origin)}


def hit_counts(grid: OccupancyGrid, outline: np.ndarray, ends) -> np.ndarray:
    """Per cell of ``outline``, the scans with a beam ending on it (``ends``: per scan, the
    (x, y) end points of its beams on boxes), as ``seen_cells`` places an end point."""
    counts = np.zeros(grid.data.size, np.int32)
    for xy in ends:
        rows, cols = outline_cells(grid, outline, xy[:, 0], xy[:, 1])
        counts[np.unique(rows * grid.width + cols)] += 1
    return counts.reshape(grid.shape)


def seen_cells(grid: OccupancyGrid, outline: np.ndarray, x, y) -> np.ndarray:
    """The cells of ``outline`` that beams ending at (x, y) hit (``outline_cells``)."""
    seen = np.zeros(grid.shape, bool)
    seen[outline_cells(grid, outline, x, y)] = True
    return seen


def outline_cells(grid: OccupancyGrid, outline: np.ndarray, x, y):
    """(rows, cols) of the cells of ``outline`` that beams ending at (x, y) hit: for each end
    point on a box's boundary, the outline cell nearest to it among the 3 x 3 cells around it
    (the point's own cell may lie just outside the cells whose centres the box covers)."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    if x.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    r, c = grid.world_to_cell(x, y)
    dr, dc = (v.ravel() for v in np.mgrid[-1:2, -1:2])
    rows, cols = r[:, None] + dr, c[:, None] + dc
    ok = grid.contains(rows, cols)
    ok[ok] = outline[rows[ok], cols[ok]]
    cx, cy = grid.cell_to_world(rows, cols)
    d = np.where(ok, np.hypot(cx - x[:, None], cy - y[:, None]), np.inf)
    k = d.argmin(axis=1)
    hit = np.isfinite(d[np.arange(k.size), k])
    return rows[hit, k[hit]], cols[hit, k[hit]]


__all__ = ["Box", "Case", "CaseError", "PlacedBox", "Person", "box_entry", "disc_entry",
           "edit_scans", "hit_counts", "laser_pose", "make_case", "outline_cells",
           "people_mask", "scan_times", "seen_cells"]
