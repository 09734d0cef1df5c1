"""The updater's faster kernels flag exactly what the plain forms did.

The walks that flag cells as they go (``walk_beams``), the decision that decides each cell
once (``decide``), the classifier's two calls (``prepare_beams``, ``classify_scan``) and the
walks into unknown space are each checked against a plain Python reference written here, on
seeded random input. Then the whole updater runs on random scans in a synthetic room (with
the paper's configuration and with ``mapupdate update``'s) against what the code before the
fused walks gave on the same scans, recorded in ``tests/data/golden/updater_room_seed*.npz``
(tests/data/golden/README.md): every report, every buffer and the output map must be the
same, bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gridmap import FREE, OCCUPIED, UNKNOWN
from tests.data.golden import golden
from updater import MapUpdater, UpdaterConfig, steps
from updater import _kernels as K

import synthetic_room as world


# --- plain references -------------------------------------------------------------------------
def plain_cells(x0, y0, x1, y1, height, width):
    """The cells (row, col) of the grid that the segment passes through, in the order it enters
    them: those it crosses with positive length (every cell's entry and exit parameters,
    sorted), and where it passes exactly through a corner, the cell beside the corner in x (the
    walks are 4-connected)."""
    cells = []
    for row, col in crossed_cells(x0, y0, x1, y1, height, width):
        if cells and cells[-1][0] != row and cells[-1][1] != col:
            cells.append((cells[-1][0], col))
        cells.append((row, col))
    return cells


def crossed_cells(x0, y0, x1, y1, height, width):
    """The cells the segment crosses with positive length (and the one it starts in), in the
    order it enters them."""
    entered = []
    rows = range(max(math.floor(min(y0, y1)), 0), min(math.floor(max(y0, y1)), height - 1) + 1)
    cols = range(max(math.floor(min(x0, x1)), 0), min(math.floor(max(x0, x1)), width - 1) + 1)
    for row in rows:
        for col in cols:
            lo, hi = 0.0, 1.0
            for start, d, a, b in ((x0, x1 - x0, col, col + 1), (y0, y1 - y0, row, row + 1)):
                if d == 0.0:
                    lo, hi = (lo, hi) if a <= start < b else (1.0, 0.0)
                else:
                    ta, tb = (a - start) / d, (b - start) / d
                    lo, hi = max(lo, min(ta, tb)), min(hi, max(ta, tb))
            inside = col <= x0 < col + 1 and row <= y0 < row + 1
            if hi - lo > 1e-9 or (inside and hi >= lo):
                entered.append((lo, not inside, row, col))     # the start cell first
    return [(row, col) for _, _, row, col in sorted(entered)]


def plain_walks(data, enclosed, sensor, hits, reach, chosen, drop_last, kind):
    """The flags of the walks of the ``chosen`` beams: each beam's cells from the sensor to
    ``reach`` of the way to its hit (without the end point's cell with ``drop_last``), those
    of ``kind``, each cell once, in the order first flagged."""
    height, width = data.shape
    flagged = {}
    for i in np.flatnonzero(chosen):
        if not reach[i] > 0:
            continue
        tx = sensor[0] + reach[i] * (hits[i, 0] - sensor[0])
        ty = sensor[1] + reach[i] * (hits[i, 1] - sensor[1])
        cells = plain_cells(sensor[0], sensor[1], tx, ty, height, width)
        if drop_last and 0 <= tx < width and 0 <= ty < height:
            cells = cells[:-1]
        for row, col in cells:
            v = int(data[row, col])
            wanted = {K.WALK_FREE: v == FREE, K.WALK_BLOCKED: v != FREE,
                      K.WALK_OPEN_UNKNOWN: v == UNKNOWN and not enclosed[row, col]}[kind]
            if wanted:
                flagged.setdefault(row * width + col)
    return list(flagged)


def random_map(rng, height=45, width=55):
    data = rng.choice(np.array([FREE, OCCUPIED, UNKNOWN], np.int8), (height, width),
                      p=[0.8, 0.1, 0.1])
    return data, rng.random((height, width)) < 0.3


def random_beams(rng, data, n=120):
    height, width = data.shape
    sensor = np.array([rng.uniform(5, width - 5), rng.uniform(5, height - 5), 0.0])
    a = rng.uniform(-math.pi, math.pi, n)
    r = rng.uniform(0.2, 40, n)
    hits = np.c_[sensor[0] + r * np.cos(a), sensor[1] + r * np.sin(a)]
    # some beams straight along an axis or diagonal, from a sensor on a cell corner
    if rng.random() < 0.5:
        sensor[:2] = np.floor(sensor[:2])
        hits[:8] = sensor[:2] + np.array([[5, 0], [0, 5], [-5, 0], [0, -5], [5, 5], [-5, 5],
                                          [5, -5], [-5, -5]], float) * rng.uniform(0.5, 4)
    return sensor, hits


# --- kernels against the references -----------------------------------------------------------
def open_map(rng, height=90, width=110):
    """Mostly free, with a few small boxes of occupied or unknown cells and scattered occupied
    ones: room for squares of clear blocks."""
    data = np.full((height, width), FREE, np.int8)
    for _ in range(height * width // 1200):
        row, col = rng.integers(0, height - 6), rng.integers(0, width - 6)
        data[row:row + rng.integers(1, 6), col:col + rng.integers(1, 6)] = \
            rng.choice([OCCUPIED, UNKNOWN])
    data[rng.random((height, width)) < 0.0002] = OCCUPIED
    return data, rng.random((height, width)) < 0.05


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("kind", [K.WALK_FREE, K.WALK_BLOCKED, K.WALK_OPEN_UNKNOWN])
@pytest.mark.parametrize("world", ["cluttered", "open"])
def test_fused_walks_flag_the_cells_of_the_plain_walks_in_order(seed, kind, world):
    """With and without the jumps across clear blocks, which leave the order as it is: the
    cells they jump over are free, and a free walk takes no jumps."""
    rng = np.random.default_rng(seed)
    if world == "cluttered":
        data, enclosed = random_map(rng)
        sensor, hits = random_beams(rng, data)
    else:       # the ties at cell corners are the cluttered world's
        data, enclosed = open_map(rng)
        sensor, hits = scan_beams(rng, data, 120, 2 * math.pi)
    reach = rng.uniform(-0.2, 1.0, len(hits))
    select = rng.random(len(hits)) < 0.7
    drop_last = bool(seed % 2)
    expect = plain_walks(data, enclosed, sensor, hits, reach, select, drop_last, kind)
    clear = steps.clear_blocks(data)
    if world == "open":
        assert (clear >= 2).mean() > 0.15     # squares to jump across
    for blocks in (K.NO_BLOCKS, clear):
        enclosed_bits = np.packbits(enclosed.reshape(-1), bitorder="little")
        marks = np.zeros_like(enclosed_bits)
        out = np.zeros(data.size + 1, np.int32)
        n = K.walk_beams(data, enclosed_bits, blocks, sensor, hits, reach, select=select,
                         want=True, drop_last=drop_last, cap=1000, kind=kind, marks=marks,
                         out=out, n=0, skip=K.NO_SKIPS)
        assert out[:n].tolist() == expect and n > (20 if world == "cluttered" else 0)
        assert np.flatnonzero(np.unpackbits(marks, bitorder="little")).tolist() == \
            sorted(expect)


def entries(data, clear, sensor, hits):
    """Where each beam's ray from the sensor first enters a cell that is not free (the
    expected point of a virtual beam along it), as ``cast_virtual`` finds it."""
    from gridmap import _kernels as G

    d = hits - sensor[:2]
    d /= np.hypot(*d.T)[:, None]
    out = np.zeros_like(hits)
    for i, (ca, sa) in enumerate(d):
        t, _ = G.first_blocked(data, clear, K.CLEAR_SHIFT, sensor[0], sensor[1], ca, sa, 1e4)
        out[i] = sensor[:2] + t * d[i]
    return out


@pytest.mark.parametrize("seed", range(8))
def test_one_walk_per_beam_flags_what_the_walks_one_after_the_other_flag(seed):
    """``walk_scan`` against the removed-obstacle, free and unknown walks of ``walk_beams``
    run one after the other (without shortcuts): the same changed and unchanged flags."""
    rng = np.random.default_rng(40 + seed)
    data, enclosed = random_map(rng) if seed % 2 else open_map(rng)
    data[rng.random(data.shape) < 0.15] = UNKNOWN
    sensor, hits = scan_beams(rng, data, 180, math.pi)
    n = len(hits)
    verdict = rng.choice(np.array([K.UNCHANGED, K.CHANGE, K.SKIPPED], np.int8), n)
    removed_reach, free_reach = rng.uniform(-0.1, 1.0, n), rng.uniform(-0.1, 1.0, n)
    into, unknown_reach = rng.random(n) < 0.5, rng.uniform(-0.1, 1.0, n)
    bits = np.packbits(enclosed.reshape(-1), bitorder="little")
    size = data.size + 1
    want = []
    for blocks, skips in ((K.NO_BLOCKS, K.NO_SKIPS), (steps.clear_blocks(data), np.zeros(n))):
        ch_marks, un_marks = np.zeros_like(bits), np.zeros_like(bits)
        changed, unchanged = np.zeros(size, np.int32), np.zeros(size, np.int32)
        if skips is K.NO_SKIPS:     # the walks one after the other
            n_ch = K.walk_beams(data, bits, blocks, sensor, hits, removed_reach, verdict,
                                K.CHANGE, True, 1000, K.WALK_BLOCKED, ch_marks, changed, 0,
                                skips)
            n_ch = K.walk_beams(data, bits, blocks, sensor, hits, unknown_reach, into, True,
                                True, 1000, K.WALK_OPEN_UNKNOWN, ch_marks, changed, n_ch,
                                skips)
            n_un = K.walk_beams(data, bits, blocks, sensor, hits, free_reach, verdict,
                                K.UNCHANGED, False, 1000, K.WALK_FREE, un_marks, unchanged, 0,
                                skips)
        else:
            n_ch, n_un = K.walk_scan(data, bits, blocks, sensor, hits, verdict, removed_reach,
                                     verdict, free_reach, skips, into, unknown_reach,
                                     entries(data, blocks, sensor, hits), 1000, ch_marks,
                                     un_marks, changed, 0, unchanged, 0)
        want.append((sorted(changed[:n_ch].tolist()), sorted(unchanged[:n_un].tolist()),
                     ch_marks.tolist(), un_marks.tolist()))
    assert want[0] == want[1]
    assert len(want[0][0]) > 50 and len(want[0][1]) > 200


@pytest.mark.parametrize("seed", range(6))
def test_walks_into_unknown_space_that_start_where_their_ray_entered_it_flag_the_same(seed):
    """Beams through a free hall into unknown space beyond it (with holes, walls and enclosed
    cells in it): ``walk_scan`` with each beam's entry point, which starts the walks that flag
    no free cell (into unknown space, with or without a removed-obstacle walk) near it,
    against ``walk_beams``' walks from the sensor."""
    rng = np.random.default_rng(70 + seed)
    data, enclosed = open_map(rng, 160, 170)
    band = rng.integers(40, 70)
    data[:, :band][rng.random((160, band)) < 0.7] = UNKNOWN     # unknown, with free holes
    data[rng.integers(0, 160, 40), rng.integers(0, band, 40)] = OCCUPIED
    sensor = np.array([rng.uniform(band + 30, 150), rng.uniform(40, 120), 0.0])
    if seed == 5:       # on a cell corner, beams along the axes and the diagonals
        sensor[:2] = np.floor(sensor[:2])
    n = 181
    a = rng.uniform(0.5, 1.0) * math.pi + math.pi / n * np.arange(n)
    a[:4] = [math.pi, 0.75 * math.pi, 1.25 * math.pi, math.pi]
    r = rng.uniform(band + 60, band + 140, n)
    hits = np.c_[sensor[0] + r * np.cos(a), sensor[1] + r * np.sin(a)]
    into, reach = rng.random(n) < 0.8, rng.uniform(0.3, 1.0, n)
    verdict = np.where(rng.random(n) < 0.3, K.UNCHANGED, K.CHANGE).astype(np.int8)
    free_reach, removed_reach = np.full(n, 0.9), np.where(rng.random(n) < 0.2, 0.9, -1.0)
    bits = np.packbits(enclosed.reshape(-1), bitorder="little")
    clear = steps.clear_blocks(data)
    got = []
    for entered in (K.NO_ENTRIES, entries(data, clear, sensor, hits)):
        ch_marks, un_marks = np.zeros_like(bits), np.zeros_like(bits)
        changed, unchanged = np.zeros(data.size + 1, np.int32), np.zeros(data.size + 1, np.int32)
        n_ch, n_un = K.walk_scan(data, bits, clear, sensor, hits, verdict, removed_reach,
                                 verdict, free_reach, np.zeros(n), into, reach, entered, 1000,
                                 ch_marks, un_marks, changed, 0, unchanged, 0)
        got.append((sorted(changed[:n_ch].tolist()), sorted(unchanged[:n_un].tolist())))
    assert got[0] == got[1] and len(got[0][0]) > 150
    # most walks into unknown space, alone or with a removed-obstacle walk, start far out
    start = np.hypot(*(entries(data, clear, sensor, hits) - sensor[:2]).T)
    for removed, beams in ((False, 60), (True, 12)):
        late = into & (verdict == K.CHANGE) & ((removed_reach > 0) == removed)
        assert late.sum() > beams and np.median(start[late]) > 25


def plain_clear_blocks(data, size):
    """Each block's Chebyshev distance (in blocks, at most 255) to the nearest block that is
    not whole on the map and free, the blocks just off the map counted as such."""
    height, width = data.shape
    bh, bw = -(-height // size), -(-width // size)
    bad = [(-1, c) for c in range(-1, bw + 1)] + [(bh, c) for c in range(-1, bw + 1)] + \
        [(r, -1) for r in range(bh)] + [(r, bw) for r in range(bh)]
    for r in range(bh):
        for c in range(bw):
            block = data[r * size:(r + 1) * size, c * size:(c + 1) * size]
            if block.shape != (size, size) or (block != FREE).any():
                bad.append((r, c))
    bad = np.array(bad)
    out = np.zeros((bh, bw), np.uint8)
    for r in range(bh):
        for c in range(bw):
            out[r, c] = min(255, int(np.max(np.abs(bad - (r, c)), axis=1).min()))
    return out


@pytest.mark.parametrize("seed, shape", [(0, (90, 110)), (1, (45, 55)), (2, (64, 64)),
                                         (3, (3, 7)), (4, (230, 170))])
def test_clear_blocks_are_the_distance_to_the_nearest_block_not_clear(seed, shape):
    data, _ = open_map(np.random.default_rng(seed), *shape) if min(shape) > 6 else \
        (np.zeros(shape, np.int8), None)
    got = steps.clear_blocks(data)
    assert np.array_equal(got, plain_clear_blocks(data, 1 << K.CLEAR_SHIFT))
    assert min(shape) < 100 or got.max() >= 3


@pytest.mark.parametrize("seed", range(8))
def test_the_cast_that_jumps_stops_where_the_cell_march_stops(seed):
    from gridmap import _kernels as G

    rng = np.random.default_rng(seed)
    data, _ = open_map(rng) if seed % 2 else random_map(rng)
    clear = steps.clear_blocks(data)
    sensor, hits = random_beams(rng, data, n=300)
    if seed == 6:       # on a cell corner, straight along the axes and diagonals
        sensor[:2] = np.floor(sensor[:2])
    d = hits - sensor[:2]
    d /= np.hypot(*d.T)[:, None]
    d[:8] = np.array([[1, 0], [0, 1], [-1, 0], [0, -1], [1, 1], [-1, 1], [1, -1], [-1, -1]]) \
        / np.hypot(1, [0, 0, 0, 0, 1, 1, 1, 1])[:, None]
    for (ca, sa), max_len in zip(d, rng.uniform(1, 150, len(d))):
        t0, s0 = G.first_hit(data, sensor[0], sensor[1], ca, sa, max_len, True)
        t1, s1 = G.first_blocked(data, clear, K.CLEAR_SHIFT, sensor[0], sensor[1], ca, sa,
                                 max_len)
        assert s1 == s0 and abs(t1 - t0) <= 1e-9 * max(1.0, t0)


def scan_beams(rng, data, n, fov):
    """A scan's beams: n evenly spaced over ``fov`` from a random heading, most of them long."""
    height, width = data.shape
    sensor = np.array([rng.uniform(0.3, 0.7) * width, rng.uniform(0.3, 0.7) * height, 0.0])
    a = rng.uniform(-math.pi, math.pi) + fov / n * np.arange(n)
    r = np.where(rng.random(n) < 0.8, rng.uniform(30, 120, n), rng.uniform(0.5, 30, n))
    return sensor, np.c_[sensor[0] + r * np.cos(a), sensor[1] + r * np.sin(a)]


@pytest.mark.parametrize("seed, n, fov", [(0, 720, 2 * math.pi), (1, 360, 2 * math.pi),
                                          (2, 1440, 2 * math.pi), (3, 181, math.pi),
                                          (4, 1081, 1.5 * math.pi), (5, 720, 2 * math.pi)])
def test_free_walks_that_skip_their_start_flag_the_cells_of_walks_from_the_sensor(seed, n,
                                                                                  fov):
    rng = np.random.default_rng(seed)
    data, _ = open_map(rng, 240, 260)
    sensor, hits = scan_beams(rng, data, n, fov)
    select = np.where(rng.random(n) < (0.97 if seed < 5 else 0.6), K.UNCHANGED, K.CHANGE)
    select = select.astype(np.int8)
    reach = np.where(rng.random(n) < 0.9, 0.98, rng.uniform(-0.1, 1.0, n))
    wrap = fov > 6.28
    skips = np.zeros(n)
    K.free_walk_skips(sensor, hits, reach, select, K.UNCHANGED, fov / n, wrap, 1000, skips)
    walked = [reach[i] * math.dist(sensor[:2], hits[i]) for i in range(n)
              if select[i] == K.UNCHANGED and reach[i] > 0]
    assert skips.sum() > (0.05 if seed == 5 else 0.2) * sum(walked)
    flagged = []
    for skip in (K.NO_SKIPS, skips):
        marks = np.zeros((data.size + 7) // 8, np.uint8)
        out = np.zeros(data.size + 1, np.int32)
        count = K.walk_beams(data, marks, K.NO_BLOCKS, sensor, hits, reach, select=select,
                             want=K.UNCHANGED, drop_last=False, cap=1000, kind=K.WALK_FREE,
                             marks=marks, out=out, n=0, skip=skip)
        flagged.append(sorted(out[:count].tolist()))
    assert flagged[0] == flagged[1] and len(flagged[0]) > 2000


def runs_of_beams(rng, n, runs, longest):
    """A few runs of consecutive beams (wrapping past the last), as a bool per beam."""
    out = np.zeros(n, bool)
    for start in rng.integers(0, n, runs):
        out[(start + np.arange(rng.integers(1, longest + 1))) % n] = True
    return out


def guarded_walk_flags(data, bits, sensor, hits, verdict, reach, into, unknown_reach, radius,
                       need):
    """The changed flags of ``walk_scan`` after the seen-surface guard around the hits of the
    beams ``need`` selects (None: every valid beam)."""
    marks = np.zeros_like(bits)
    K.mark_seen_surfaces(data, bits, hits, verdict, radius, min(radius, 1.0), marks,
                         np.zeros(data.size, np.int32), need)
    changed, unchanged = np.zeros(data.size + 1, np.int32), np.zeros(data.size + 1, np.int32)
    n_ch, _ = K.walk_scan(data, bits, steps.clear_blocks(data), sensor, hits, verdict, reach,
                          verdict, np.full(len(hits), 0.98), np.zeros(len(hits)), into,
                          unknown_reach, K.NO_ENTRIES, 1000, marks, np.zeros_like(bits),
                          changed, 0, unchanged, 0)
    return changed[:n_ch].tolist()


@pytest.mark.parametrize("seed, n, fov, radius", [
    (0, 720, 2 * math.pi, 1.5), (1, 360, 2 * math.pi * 359 / 360, 1.5), (2, 181, math.pi, 3.0),
    (3, 400, 2.3 * math.pi, 1.5), (4, 90, 1.9 * math.pi, 2.0), (5, 1081, 1.5 * math.pi, 1.5)])
def test_the_guard_around_the_hits_near_a_changed_walk_flags_as_the_whole_guard(seed, n, fov,
                                                                                 radius):
    """The seen-surface guard only around the hits ``guard_needed`` keeps (those near a walk
    that flags changed cells) leaves the walks the very flags of the guard around every hit,
    on cluttered maps where the walks cross many guarded cells; scans of a turn, nearly a
    turn, half a turn and more than a turn. The guard bites (it takes flags away), the
    pruning too (it leaves hits out), and guarding only the hits of a walking beam and its
    neighbours (rho 0) would change the flags."""
    rng = np.random.default_rng(70 + seed)
    data, enclosed = random_map(rng, 90, 110)
    bits = np.packbits(enclosed.reshape(-1), bitorder="little")
    height, width = data.shape
    sensor = np.array([rng.uniform(0.3, 0.7) * width, rng.uniform(0.3, 0.7) * height, 0.0])
    a = rng.uniform(-math.pi, math.pi) + fov / n * np.arange(n)
    r = np.where(rng.random(n) < 0.1, rng.uniform(0.2, 4.0, n), rng.uniform(4.0, 70.0, n))
    hits = np.c_[sensor[0] + r * np.cos(a), sensor[1] + r * np.sin(a)]
    verdict = np.where(runs_of_beams(rng, n, 4, n // 20), K.CHANGE, K.UNCHANGED)
    verdict = verdict.astype(np.int8)
    verdict[rng.random(n) < 0.05] = K.INVALID
    hits[verdict == K.INVALID] = np.nan
    reach = rng.uniform(-0.1, 1.0, n)
    into = runs_of_beams(rng, n, 3, n // 30) & (verdict != K.INVALID)
    unknown_reach = rng.uniform(-0.1, 1.0, n)
    need = np.zeros(n, bool)
    count = K.guard_needed(sensor, hits, verdict, verdict, reach, into, unknown_reach, radius,
                           fov / n, need)
    assert count == need.sum() and 0 < count < 0.8 * np.count_nonzero(verdict != K.INVALID)
    assert not need[verdict == K.INVALID].any()
    every = guarded_walk_flags(data, bits, sensor, hits, verdict, reach, into, unknown_reach,
                               radius, None)
    assert guarded_walk_flags(data, bits, sensor, hits, verdict, reach, into, unknown_reach,
                              radius, need) == every
    unguarded = guarded_walk_flags(data, bits, sensor, hits, verdict, reach, into,
                                   unknown_reach, 0.0, np.zeros(n, bool))
    assert len(unguarded) > len(every) > 20
    narrow = np.zeros(n, bool)      # rho = 1e-6: the walking beams and their neighbours
    K.guard_needed(sensor, hits, verdict, verdict, reach, into, unknown_reach,
                   -math.sqrt(2.0), fov / n, narrow)
    assert guarded_walk_flags(data, bits, sensor, hits, verdict, reach, into, unknown_reach,
                              radius, narrow) != every
    # walks from a quarter of the beams: every valid hit, not worth sorting out
    into = (np.arange(n) % 4 == 0) & (verdict != K.INVALID)
    K.guard_needed(sensor, hits, verdict, verdict, reach, into, np.ones(n), radius, fov / n,
                   need)
    assert np.array_equal(need, verdict != K.INVALID)


def test_a_walk_stops_at_the_cap_as_the_listed_walk_does():
    data = np.zeros((20, 200), np.int8)
    sensor, hits = np.array([1.5, 10.5, 0.0]), np.array([[190.5, 10.5]])
    out = np.zeros(data.size + 1, np.int32)
    marks = np.zeros((data.size + 7) // 8, np.uint8)
    n = K.walk_beams(data, marks, K.NO_BLOCKS, sensor, hits, np.ones(1),
                     select=np.ones(1, np.bool_), want=True, drop_last=False, cap=25,
                     kind=K.WALK_FREE, marks=marks, out=out, n=0, skip=K.NO_SKIPS)
    assert out[:n].tolist() == [10 * 200 + c for c in range(1, 26)]


@pytest.mark.parametrize("seed", range(3))
def test_walks_into_unknown_space_match_the_plain_rule(seed):
    rng = np.random.default_rng(20 + seed)
    data, enclosed = random_map(rng)
    sensor, hits = random_beams(rng, data)
    ranges = np.hypot(*(hits - sensor[:2]).T) * 0.05
    ranges[::9] = np.nan
    expected = sensor[:2] + (hits - sensor[:2]) * rng.uniform(0.3, 1.2, (len(hits), 1))
    directions = (hits - sensor[:2]) / np.hypot(*(hits - sensor[:2]).T)[:, None]
    found = rng.random(len(hits)) < 0.8
    short = 0.075
    # the plain rule: the expected ray ends at an unknown cell, the beam is valid and longer
    # than ``short``, and walks to ``short`` short of its hit
    into = np.zeros(len(hits), bool)
    for i in range(len(hits)):
        col, row = (math.floor(v) for v in expected[i] + 1e-4 * directions[i])
        on_map = 0 <= row < data.shape[0] and 0 <= col < data.shape[1]
        into[i] = found[i] and (not on_map or data[row, col] == UNKNOWN) and ranges[i] > short
    reach = np.where(into, 1.0 - short / np.where(into, ranges, 1.0), 0.0)
    expect = plain_walks(data, enclosed, sensor, hits, reach, into, True, K.WALK_OPEN_UNKNOWN)
    bits = np.packbits(enclosed.reshape(-1), bitorder="little")
    marks = np.zeros_like(bits)
    out = np.zeros(data.size + 1, np.int32)
    n = K.flag_unknown_seen_through(data, bits, steps.clear_blocks(data), sensor, hits, ranges,
                                    expected, directions,
                                    found, short=short, marks=marks, cap=1000,
                                    into=np.zeros(len(hits), np.bool_),
                                    reach=np.zeros(len(hits)), out=out, n=0)
    assert out[:n].tolist() == expect and n > 0


@pytest.mark.parametrize("few, support", [(0, True), (3, True), (3, False), (0, False)])
def test_decide_decides_each_cell_once_and_leaves_the_stamps_clear(few, support):
    rng = np.random.default_rng(7)
    size, width = 40 * 30, 30
    ref = rng.choice(np.array([FREE, OCCUPIED, UNKNOWN], np.int8), size)
    hist = rng.integers(0, 1 << 10, size).astype(np.uint16)
    hist[rng.random(size) < 0.5] = 0
    seen = rng.integers(0, 12, size).astype(np.uint8)
    moved = rng.integers(0, size, 300).astype(np.int32)
    moved[::3] = -1 - moved[::3]            # crossed the threshold: the neighbours too
    stamp = np.zeros((size + 7) // 8, np.uint8)
    decided = np.zeros_like(stamp)
    delta = K.decide(hist, seen, ref, decided, moved, width, 0x3FF, 7, few, support, stamp)
    assert not stamp.any()
    # the plain rule over every cell the entries name, and nothing else
    named = set()
    for m in moved.tolist():
        idx = m if m >= 0 else -1 - m
        row, col = divmod(idx, width)
        near = [(r, c) for r in (row - 1, row, row + 1) for c in (col - 1, col, col + 1)
                if 0 <= r < size // width and 0 <= c < width] if m < 0 and (few or support) \
            else [(row, col)]
        named |= {r * width + c for r, c in near}
    expect = np.zeros(size, bool)
    for idx in named:
        expect[idx] = plain_changed(hist, seen, ref, idx, width, few, support)
    got = np.unpackbits(decided, bitorder="little")[:size].astype(bool)
    assert (got == expect).all() and delta == expect.sum() > 0


def plain_changed(hist, seen, ref, idx, width, few, support, threshold=7, window=10):
    """docs/algorithm.md's decision rule for one cell, written out."""
    def count(j):
        return bin(int(hist[j]) & ((1 << window) - 1)).count("1")

    def neighbours():
        row, col = divmod(idx, width)
        return [r * width + c for r in (row - 1, row, row + 1) for c in (col - 1, col, col + 1)
                if 0 <= r < len(ref) // width and 0 <= c < width and r * width + c != idx]

    n = count(idx)
    if n >= threshold:
        return True
    if few and few <= n == seen[idx] < threshold:
        if ref[idx] != OCCUPIED or not any(
                ref[j] == OCCUPIED and seen[j] and count(j) < min(int(seen[j]), window)
                for j in neighbours()):
            return True
    if support:
        same = [j for j in neighbours() if (ref[j] != FREE) == (ref[idx] != FREE)]
        return n + sum(count(j) >= threshold for j in same) >= threshold
    return False


def test_per_beam_distances_are_the_configuration_s_to_the_bit():
    cfg = UpdaterConfig(pairing_distance_slope=0.021, radius_far_range=7.3)
    rng = np.random.default_rng(3)
    r = np.r_[rng.uniform(0, 25, 500), np.nan, 0.2, 10.0, 7.3]
    ws = steps.Workspace()
    ws.for_beams(len(r), len(r), 10)
    K.beam_distances(r, 0.05, ws.settings(cfg, 0.05).dist, ws.pairing, ws.tol, ws.skip, ws.reach,
                     ws.free_reach)
    pairing, tol, skip = steps.beam_distances(r, 0.05, cfg)
    for got, want in ((ws.pairing, pairing), (ws.tol, tol), (ws.skip, skip),
                      (ws.reach, 1.0 - skip / r), (ws.free_reach, np.full(len(r), 0.98))):
        assert np.array_equal(got, want, equal_nan=True)


# --- the whole updater, against the code before ----------------------------------------------
def room_session(seconds, seed):
    """A map of the room with one box, a world with that box moved and a new one: scans from
    a circling robot with noisy poses (some beams lost)."""
    shapes_map = world.room_walls() + [world.Rect(4.0, 4.0, 5.0, 4.6), world.Circle(8, 3, 0.4)]
    shapes_now = world.room_walls() + [world.Rect(5.2, 6.4, 6.2, 7.0), world.Circle(8, 3, 0.4),
                                       world.Rect(2.0, 8.0, 2.6, 8.6)]
    ref = world.rasterise(world.room_walls() + [world.Circle(8, 3, 0.4)],
                          hollow=[world.Rect(4.0, 4.0, 5.0, 4.6)])
    rng = np.random.default_rng(seed)
    drive = world.Drive(seconds=seconds, seed=seed, radius=rng.uniform(2.0, 3.5))
    scans = []
    for true, noisy, t in drive.steps():
        scan = world.full_scan(shapes_now, true, t, beams=int(rng.choice([360, 720])))
        scan.ranges[rng.random(scan.beams) < 0.03] = np.nan
        scans.append((scan, noisy, true))
    return ref, scans, shapes_map


def unknown_corner(ref):
    """The map with its top right quarter unknown: space to grow into."""
    data = ref.data.copy()
    h, w = data.shape
    data[h // 2:, w // 2:] = UNKNOWN
    return type(ref)(data, ref.resolution, ref.origin)


# (seed, robot) of the runs recorded in tests/data/golden/updater_room_seed{seed}.npz
ROOM_CASES = [(0, False), (1, True), (2, True), (3, False)]


def room_case(seed: int, robot: bool):
    """The reference map, the scans ((scan, noisy pose, true pose) each) and the configuration
    of a run of ``ROOM_CASES``: the paper's rules with every scan processed, or (``robot``)
    ``mapupdate update``'s additions as the code before ran them (growth into the unknown of
    the map's top right quarter, the unanimous rule, the gate's confirmation), every other
    key at its default."""
    ref, scans, _ = room_session(14.0, seed)
    cfg = UpdaterConfig(gating=False)
    if robot:
        ref = unknown_corner(ref)
        cfg = UpdaterConfig(grow_into_unknown=True, unanimous_min=3, gate_confirm=True,
                            gate_min_interval=0.0, gate_min_distance=0.2,
                            gate_min_rotation_deg=20.0, fill_gaps=seed == 2,
                            virtual_to_measured_ratio=1 + seed % 2)
    return ref, scans, cfg


def same_config(cfg: UpdaterConfig, recorded: dict) -> None:
    """The configuration is the one the golden file was recorded with (keys added since then
    aside)."""
    now = golden.as_recorded(cfg.to_dict())
    assert {k: now.get(k) for k in recorded} == recorded


@pytest.mark.parametrize("seed, robot", ROOM_CASES)
def test_the_updater_gives_what_it_gave_before_to_the_bit(seed, robot):
    """The recorded reports of the code before (its flag counts less those that would have
    changed nothing: the code before flagged the free cells with settled buffers too, where no
    changed flag came first, and made changed flags in buffers full of them, on the free
    cells of M the new-obstacle and fill_gaps flags; the walks flag the others), per-beam
    verdicts, buffers, hit buffers, flag counts, statistics and output map."""
    ref, scans, cfg = room_case(seed, robot)
    want = golden.Golden(f"updater_room_seed{seed}")
    want.check_inputs(golden.fingerprint(ref.data, scans))
    same_config(cfg, want.facts["config"])
    after = MapUpdater(ref, cfg)
    verdicts = golden.unpack(want["verdicts"], want["verdict_lengths"])
    skipped = 0
    for k, (scan, noisy, true) in enumerate(scans):
        a = after.process(scan, noisy, odometry=true)
        b = want.facts["reports"][k]
        assert a.unchanged_flags == b["unchanged_flags"] - want["settled_unchanged"][k]
        assert a.changed_flags == b["changed_flags"] - want["full_changed"][k]
        assert a.new_obstacle_flags == b["new_obstacle_flags"] - want["full_new_obstacle"][k]
        skipped += b["changed_flags"] - a.changed_flags
        flags = {"unchanged_flags": 0, "changed_flags": 0, "new_obstacle_flags": 0}
        assert {**golden.as_recorded(a.summary()), **flags} == {**b, **flags}
        assert (a.verdicts is None and verdicts[k] is None) or \
            np.array_equal(a.verdicts, verdicts[k])
    assert skipped > 0
    mask = np.uint16(steps.buffer_mask(cfg))
    assert np.array_equal(after.updated_map().data, want["map"])
    assert np.array_equal(after._hist & mask, want["hist"])
    assert np.array_equal(after._hits.dense(), want["hits"])
    # the flag counts, kept above the flags now, are alike up to T, past which no rule tells a
    # free cell's apart (a settled cell's count stops there, as no walk flags it), and every
    # cell's up to N_b, past which no rule tells any apart (a count stops where changed flags
    # fill the buffer)
    if want["seen"].size:
        counts, counts_before = after._flag_counts(), want["seen"].reshape(-1)
        for bound in (cfg.threshold, cfg.buffer_size):
            cells = slice(None) if bound == cfg.threshold else ref.data.reshape(-1) != FREE
            assert np.array_equal(np.minimum(counts, bound)[cells],
                                  np.minimum(counts_before, bound)[cells])
        assert np.all(counts <= counts_before) and np.any(counts < counts_before)
    else:
        assert after._flag_counts() is None and np.array_equal(after._hist, want["hist"])
    assert golden.as_recorded(after.stats) == want.facts["stats"]
    assert after.n_changed == want.facts["n_changed"] > 0
    # between scans the changed-flag marks are set on the cells whose buffers are full of
    # changes alone, the unchanged-flag marks on the settled free cells alone
    full = (after._hist.reshape(-1) & mask) == mask
    assert full.any() and np.array_equal(
        np.unpackbits(after._ch_marks, bitorder="little")[:ref.data.size], full)
    quiet = settled_free_cells(ref.data, after._hist & mask, after._flag_counts(), cfg)
    assert np.array_equal(np.unpackbits(after._un_marks, bitorder="little")[:ref.data.size],
                          quiet)


def settled_free_cells(data, flags, counts, cfg) -> np.ndarray:
    """Per cell (flat): free in M, every flag in its buffer unchanged and, when the flags are
    counted, counted T times or more (an unchanged flag then changes nothing a rule reads)."""
    out = (data.reshape(-1) == FREE) & (flags.reshape(-1) == 0)
    if counts is not None:
        out &= counts.reshape(-1) >= cfg.threshold
    return out
