"""The updater's kernels (gathered in updater._kernels) one by one against a plain NumPy /
Python reference, on seeded random input, and the classifier's steps of updater.steps where
they add something of their own: the per-beam distances against docs/algorithm.md's numbers
written out here. The references are written for clarity, not speed, here or in
naive_updater.py (the steps written plainly, which test_updater_fused.py sets beside the
fused scan), and share no code with the kernels or the configuration."""

from __future__ import annotations

import math

import numpy as np
import pytest

import naive_updater as naive
from gridmap import FREE, Pose2D, Scan
from gridmap import OCCUPIED as OCC
from gridmap import UNKNOWN as UNK
from updater import UpdaterConfig, steps
from updater import _kernels as K
from updater._arguments import SETTINGS, Buffers

import synthetic_room as world


# --- references -------------------------------------------------------------------------------
def ref_expected_point(data, x0, y0, a, max_len):
    """March the ray cell by cell: the entry point of the first occupied-or-unknown cell, or the
    point where it leaves the grid; None when nothing blocks within max_len."""
    h, w = data.shape
    x1, y1 = x0 + max_len * math.cos(a), y0 + max_len * math.sin(a)
    for r, c in zip(*naive.segment_cells(x0, y0, x1, y1, h, w)):
        if data[r, c] != FREE:
            ts = [0.0]
            for p, d, lo, hi in ((x0, math.cos(a), c, c + 1), (y0, math.sin(a), r, r + 1)):
                if d != 0:
                    ts.append(min((lo - p) / d, (hi - p) / d))
            t = max(ts)
            return x0 + t * math.cos(a), y0 + t * math.sin(a)
    if 0 <= x1 < w and 0 <= y1 < h:
        return None
    ts = []
    for p, d, lo, hi in ((x0, math.cos(a), 0, w), (y0, math.sin(a), 0, h)):
        if d != 0:
            ts.append(max((lo - p) / d, (hi - p) / d))
    t = min(ts)
    return x0 + t * math.cos(a), y0 + t * math.sin(a)


def ref_popcount(v):
    return bin(int(v)).count("1")


def random_map(rng, h=40, w=50, p_occ=0.08, p_unk=0.05):
    data = np.full((h, w), FREE, np.int8)
    u = rng.random((h, w))
    data[u < p_occ] = OCC
    data[(u >= p_occ) & (u < p_occ + p_unk)] = UNK
    return data


def random_hits(rng, n, h, w, sensor):
    ranges = rng.uniform(0.05, 2.0, n)                    # [m]
    a = sensor[2] + rng.uniform(-math.pi, math.pi, n)
    res = 0.05
    return ranges, sensor[0] + ranges / res * np.cos(a), sensor[1] + ranges / res * np.sin(a)


# --- bits -------------------------------------------------------------------------------------
def test_popcount_and_bits():
    for v in [0, 1, 0x3FF, 0xFFFF, 0x8001, 0x5555, 12345]:
        assert K.popcount16(np.uint16(v)) == ref_popcount(v)
    bits = np.zeros(4, np.uint8)
    assert K.test_and_set(bits, 13) and not K.test_and_set(bits, 13)
    assert K.bit_get(bits, 13) == 1 and K.bit_get(bits, 12) == 0
    assert np.unpackbits(bits, bitorder="little").nonzero()[0].tolist() == [13]


def test_clear_bits_clears_the_listed_cells_only():
    rng = np.random.default_rng(9)
    bits = rng.integers(0, 256, 40).astype(np.uint8)
    cells = rng.choice(320, 60, replace=False).astype(np.int32)
    expect = np.unpackbits(bits, bitorder="little").astype(bool)
    expect[cells[:45]] = False
    K.clear_bits(bits, cells, 45)
    assert (np.unpackbits(bits, bitorder="little").astype(bool) == expect).all()


# --- docs/algorithm.md's range-dependent distances, written out here -------------------------
def pairing_distance(r):
    """D(r) [m]: 0.15 m at 0.2 m, slope 0.013265, at most 0.30 m."""
    return min(0.15 + 0.013265 * (r - 0.2), 0.30)


def new_obstacle_radius(r):
    """tol(r) [m]: 0.10 m at 0 m rising linearly to 0.20 m at 10 m, 0.20 m beyond."""
    return 0.10 + 0.10 * min(r, 10.0) / 10.0


def removed_skip(r):
    """|p_i - p_th| [m]: 2 % of the range, at least 0.15 m."""
    return max(0.02 * r, 0.15)


def test_written_out_distances_have_the_algorithms_values():
    assert pairing_distance(0.2) == 0.15 and pairing_distance(20.0) == 0.30
    assert pairing_distance(10.0) == pytest.approx(0.28, abs=1e-4)
    assert new_obstacle_radius(0.0) == 0.10 and new_obstacle_radius(5.0) == pytest.approx(0.15)
    assert new_obstacle_radius(10.0) == pytest.approx(0.20) and new_obstacle_radius(17.0) == 0.20
    assert removed_skip(1.0) == 0.15 and removed_skip(7.5) == 0.15
    assert removed_skip(10.0) == pytest.approx(0.20) and removed_skip(15.0) == pytest.approx(0.30)


def test_per_beam_distances_follow_the_algorithm():
    r = np.r_[np.linspace(0.05, 20.0, 400), 0.2, 5.0, 10.0, 12.0]
    pairing, tol, skip = steps.beam_distances(r, 0.05, UpdaterConfig())
    assert pairing == pytest.approx([pairing_distance(x) / 0.05 for x in r], abs=1e-9)
    assert tol == pytest.approx([new_obstacle_radius(x) / 0.05 for x in r], abs=1e-9)
    assert skip == pytest.approx([removed_skip(x) for x in r], abs=1e-12)


# --- 1. beam classifier -----------------------------------------------------------------------
def test_valid_ranges():
    ranges = np.array([1.0, np.nan, np.inf, -1.0, 0.0, 0.01, 2.0, 17.99, 18.0, 25.0], np.float32)
    r, valid = np.zeros(ranges.size), np.zeros(ranges.size, np.bool_)
    K.valid_ranges(ranges, 0.0, 18.0, r, valid)
    assert valid.tolist() == [True, False, False, False, False, True, True, True, False, False]
    assert (r[valid] == ranges[valid].astype(np.float64)).all() and np.isnan(r[~valid]).all()
    K.valid_ranges(ranges, 0.5, 18.0, r, valid)           # the scan's range_min applies too
    assert not valid[5] and valid[0] and np.isnan(r[5])


def test_beam_directions():
    out = np.zeros((50, 2))
    K.beam_directions(0.4, -1.0, 0.1, out)
    a = [0.4 + -1.0 + j * 0.1 for j in range(50)]
    assert out[:, 0].tolist() == pytest.approx([math.cos(x) for x in a], abs=1e-15)
    assert out[:, 1].tolist() == pytest.approx([math.sin(x) for x in a], abs=1e-15)


def test_beam_endpoints():
    r = np.array([1.0, np.nan, 0.01, 2.0, 17.99, np.nan])
    valid = ~np.isnan(r)
    sensor = np.array([10.3, 20.7, 0.4])
    a = 0.4 - 1.0 + 0.1 * np.arange(r.size)
    directions = np.c_[np.cos(a), np.sin(a)]
    hits = np.zeros((r.size, 2))
    n_valid, walk, box = K.beam_endpoints(r, valid, sensor, directions, 0.05, hits)
    assert n_valid == 4 and np.isnan(hits[~valid]).all()
    np.testing.assert_allclose(hits[valid, 0], 10.3 + r[valid] / 0.05 * np.cos(a[valid]),
                               atol=1e-9)
    np.testing.assert_allclose(hits[valid, 1], 20.7 + r[valid] / 0.05 * np.sin(a[valid]),
                               atol=1e-9)
    cols, rows = np.floor(hits[valid, 0]).astype(int), np.floor(hits[valid, 1]).astype(int)
    assert walk == int(np.sum(np.abs(cols - 10) + np.abs(rows - 20) + 7))
    assert box == (max(cols.max(), 10) - min(cols.min(), 10) + 3) * \
        (max(rows.max(), 20) - min(rows.min(), 20) + 3)


@pytest.mark.parametrize("seed, p_occ", [(0, 0.03), (1, 0.03), (2, 0.03), (3, 0.002),
                                         (4, 0.002)])
def test_cast_virtual_against_cell_march(seed, p_occ):
    rng = np.random.default_rng(seed)
    data = random_map(rng, p_occ=p_occ, p_unk=p_occ / 2)
    sensor = np.array([rng.uniform(5, 45), rng.uniform(5, 35), rng.uniform(-3, 3)])
    data[int(sensor[1]), int(sensor[0])] = FREE
    m = 300
    step = 2 * math.pi / m
    a = sensor[2] - math.pi + step * np.arange(m)
    directions = np.c_[np.cos(a), np.sin(a)]
    expected, found = np.zeros((m, 2)), np.zeros(m, np.bool_)
    max_len = rng.uniform(10, 40)
    K.cast_virtual(data, steps.clear_blocks(data), sensor, directions, max_len, expected, found)
    for j in range(m):
        p = ref_expected_point(data, sensor[0], sensor[1], a[j], max_len)
        assert found[j] == (p is not None)
        if p is not None:
            assert abs(expected[j, 0] - p[0]) < 1e-6 and abs(expected[j, 1] - p[1]) < 1e-6


def ref_classify(hits, valid, pairing, expected, found, ratio, half, wrap):
    m = len(expected)
    out = []
    for i in range(len(hits)):
        if not valid[i]:
            out.append(False)
            continue
        js = [i * ratio + o for o in range(-half, half + 1)]
        js = [j % m for j in js] if wrap else [j for j in js if 0 <= j < m]
        out.append(not any(found[j] and math.dist(hits[i], expected[j]) < pairing[i]
                           for j in js))
    return np.array(out)


@pytest.mark.parametrize("ratio,wrap", [(1, False), (1, True), (2, False), (3, True)])
def test_classify_against_brute_force(ratio, wrap):
    rng = np.random.default_rng(ratio * 10 + wrap)
    n = 120
    m = n * ratio
    expected = rng.uniform(0, 20, (m, 2))
    found = rng.random(m) > 0.2
    # hit points near expected points some of the time, elsewhere otherwise
    src = (np.arange(n) * ratio + rng.integers(-12, 13, n)) % m
    near = rng.random(n) < 0.6
    hits = np.where(near[:, None], expected[src] + rng.normal(0, 3, (n, 2)),
                    rng.uniform(0, 20, (n, 2)))
    pairing = np.array([pairing_distance(x) / 0.05 for x in rng.uniform(0.1, 15, n)])
    valid = rng.random(n) > 0.1
    out = np.zeros(n, np.bool_)
    count = K.classify(hits, valid, pairing, expected, found, 6, wrap, out)
    expect = ref_classify(hits, valid, pairing, expected, found, ratio, 6, wrap)
    assert out.tolist() == expect.tolist() and count == expect.sum()
    assert 10 < count < n - 10      # both outcomes exercised


def test_classify_window_wraps_only_when_asked():
    n = 100
    expected = np.full((n, 2), 50.0)
    found = np.zeros(n, np.bool_)
    found[n - 2] = True                     # the only expected point: two beams before beam 0
    expected[n - 2] = 10.0, 10.0
    hits = np.full((n, 2), 90.0)
    hits[0] = 10.1, 10.0
    valid, pairing = np.ones(n, np.bool_), np.full(n, 3.0)
    out = np.zeros(n, np.bool_)
    K.classify(hits, valid, pairing, expected, found, 4, False, out)
    assert out[0]
    K.classify(hits, valid, pairing, expected, found, 4, True, out)
    assert not out[0]


def one_beam_towards_a_wall(r, gap, cfg):
    """A map with an occupied column at col 460 and one beam of range r [m] along +x that
    ends ``gap`` [m] in front of it (behind it when negative). Returns the classified beams."""
    data = np.zeros((20, 480), np.int8)
    data[:, 460] = OCC
    gx = 460.0 - (gap + r) / 0.05
    scan = Scan(np.array([r], np.float32), 0.0, 0.01, 0.0, 30.0)
    return steps.classify_beams(data, scan, np.array([gx, 10.5, 0.0]), 0.05, cfg,
                                steps.Workspace())


@pytest.mark.parametrize("r", [0.2, 1.0, 5.0, 10.0, 12.0, 20.0])
def test_classifier_verdict_flips_exactly_at_the_pairing_distance(r):
    # The beam's own virtual beam ends where the measured one would on M; the only thing
    # that decides the verdict is how far the hit lies from that expected point.
    r = float(np.float32(r))                 # a scan holds float32 ranges
    cfg = UpdaterConfig(max_range=25.0, min_run=1)
    for side in (1.0, -1.0):
        for factor, change in ((1 - 1e-6, False), (1 + 1e-6, True)):
            beams = one_beam_towards_a_wall(r, side * factor * pairing_distance(r), cfg)
            assert beams.valid == 1 and beams.raw_changes == int(change), (r, side, factor)
            assert beams.verdict[0] == (K.CHANGE if change else K.UNCHANGED)


def reference_runs(change, hits, min_run, min_width, wrap):
    """Which changes the run filter keeps, written out: split the beams into maximal runs of
    changes (joined across the ends when ``wrap``), keep a run of min_run or more, or of two
    or more whose end hits lie min_width apart (min_width > 0)."""
    n = len(change)
    runs, current = [], []
    for i in range(n):
        if change[i]:
            current.append(i)
        elif current:
            runs.append(current)
            current = []
    if current:
        runs.append(current)
    if wrap and len(runs) > 1 and runs[0][0] == 0 and runs[-1][-1] == n - 1:
        runs = [runs[-1] + runs[0]] + runs[1:-1]
    keep = np.zeros(n, bool)
    for run in runs:
        span = math.dist(hits[run[0]], hits[run[-1]])
        if len(run) >= min_run or (min_width > 0 and len(run) >= 2 and span >= min_width):
            keep[run] = True
    return keep


@pytest.mark.parametrize("seed", range(6))
def test_run_filter_against_reference(seed):
    rng = np.random.default_rng(seed)
    n = 90
    change = rng.random(n) < 0.45
    hits = np.cumsum(rng.uniform(0.5, 4.0, (n, 2)), axis=0)     # cells apart, beam to beam
    for min_run, min_width, wrap in ((3, 0.0, False), (3, 4.0, False), (3, 4.0, True),
                                     (4, 9.0, True), (1, 0.0, True)):
        keep = np.zeros(n, np.bool_)
        kept = K.run_filter(change, min_run, wrap, keep, hits, min_width)
        want = reference_runs(change, hits, min_run, min_width, wrap)
        assert np.array_equal(keep, want) and kept == want.sum()
    # a run of two kept for its width only: the width test is what keeps it
    two = np.zeros(n, np.bool_)
    two[10:12] = True
    assert K.run_filter(two, 3, False, np.zeros(n, np.bool_), hits, 0.0) == 0
    wide = math.dist(hits[10], hits[11])
    assert K.run_filter(two, 3, False, np.zeros(n, np.bool_), hits, wide) == 2
    assert K.run_filter(two, 3, False, np.zeros(n, np.bool_), hits, wide * 1.01) == 0


# --- walks along beams (walk_scan, one walk per beam) -----------------------------------------
def walks(data, sensor, hits, verdict, removed_reach, free_reach, cap=300):
    """The removed-obstacle walks (CHANGE beams) and free walks (UNCHANGED beams) of
    ``walk_scan``, as a scan runs them but for its shortcuts (no clear blocks, no late
    starts): (changed cells, unchanged cells), each in the order flagged, and the two marks."""
    n = len(hits)
    ch_marks, un_marks = (np.zeros((data.size + 7) // 8, np.uint8) for _ in range(2))
    changed, unchanged = np.zeros(data.size + 1, np.int32), np.zeros(data.size + 1, np.int32)
    n_ch, n_un = K.walk_scan(data, np.zeros_like(ch_marks), K.NO_BLOCKS, sensor, hits, verdict,
                             removed_reach, verdict, free_reach, np.zeros(n), np.zeros(n, bool),
                             np.zeros(n), K.NO_ENTRIES, cap, ch_marks, un_marks, changed, 0,
                             unchanged, 0)
    return changed[:n_ch].tolist(), unchanged[:n_un].tolist(), ch_marks, un_marks


def listed(rows_cols, width):
    rows, cols = rows_cols
    return (rows * width + cols).tolist()


@pytest.mark.parametrize("seed", [0, 1])
def test_walk_against_reference(seed):
    """A free walk on a free map lists every cell it crosses, a removed-obstacle walk on an
    unknown map every cell but its last (sensors off the map too)."""
    rng = np.random.default_rng(seed)
    for trial in range(500):
        sensor = np.array([rng.uniform(-5, 55), rng.uniform(-5, 45), 0.0])
        hit = (sensor[:2] + rng.uniform(-40, 40, 2))[None, :]
        reach, drop_last = np.array([rng.uniform(0.2, 1.0)]), bool(rng.random() < 0.5)
        data = np.full((40, 50), UNK if drop_last else FREE, np.int8)
        verdict = np.array([K.CHANGE if drop_last else K.UNCHANGED], np.int8)
        changed, unchanged, _, _ = walks(data, sensor, hit, verdict, reach, reach)
        expect = listed(naive.walk_cells(sensor, hit[0], reach[0], drop_last, data.shape), 50)
        assert (changed if drop_last else unchanged) == expect


# --- 2./3. evaluators -------------------------------------------------------------------------
def test_disc_is_free_against_brute_force():
    rng = np.random.default_rng(5)
    data = random_map(rng, h=30, w=30, p_occ=0.01, p_unk=0.01)
    for trial in range(2000):
        px, py = rng.uniform(-1, 31, 2)
        rad = rng.uniform(0.1, 5)
        assert K.disc_is_free(data, px, py, rad) == naive.disc_is_free(data, px, py, rad)


def _evaluator_input(seed):
    rng = np.random.default_rng(seed)
    data = random_map(rng, p_occ=0.05, p_unk=0.03)
    sensor = np.array([rng.uniform(10, 40), rng.uniform(10, 30), 0.3])
    r, hx, hy = random_hits(rng, 80, *data.shape, sensor)
    verdict = rng.choice(np.array([K.INVALID, K.UNCHANGED, K.SKIPPED, K.CHANGE], np.int8), 80)
    return data, sensor, r, np.c_[hx, hy], verdict


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_flag_changed_kernels_against_reference(seed):
    data, sensor, r, hits, verdict = _evaluator_input(seed)
    data[data.shape[0] // 2:] = FREE      # an open half, where new obstacles can be flagged
    tol = np.array([new_obstacle_radius(x) / 0.05 for x in r])
    reach = np.array([1 - removed_skip(x) / x for x in r])
    removed, _, marks, _ = walks(data, sensor, hits, verdict, reach, np.zeros(len(r)))
    out = np.zeros(5000, np.int32)
    out[:len(removed)] = removed
    n, n_all = len(removed), K.flag_new_obstacles(data, hits, tol, verdict, marks, out,
                                                  len(removed))
    new = naive.new_obstacle_cells(data, hits, tol, verdict)
    assert removed == naive.removed_obstacle_cells(data, sensor, hits, reach, verdict)
    assert sorted(out[n:n_all].tolist()) == sorted(new)
    assert n > 0 and n_all > n and (reach <= 0).any()     # short beams walk nowhere
    # every listed cell is marked, and only those
    assert sorted(np.flatnonzero(np.unpackbits(marks, bitorder="little"))) == \
        sorted(removed + new)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("free_fraction, free_margin", [(0.98, 0.0), (0.9, 0.075)])
def test_flag_unchanged_kernels_against_reference(seed, free_fraction, free_margin):
    data, sensor, r, hits, verdict = _evaluator_input(seed)
    occupied = np.argwhere(data == OCC)[:len(hits):4]     # some hits on occupied cells
    hits[:len(occupied)] = occupied[:, ::-1] + 0.5
    reach = np.array([max(free_fraction, 1 - free_margin / x) if 0 < free_margin < x
                      else free_fraction for x in r])
    _, free, _, marks = walks(data, sensor, hits, verdict, np.zeros(len(r)), reach)
    out = np.zeros(5000, np.int32)
    out[:len(free)] = free
    n = len(free)
    n_all = K.flag_occupied_unchanged(data, hits, verdict, marks, out, n)
    assert free == naive.free_cells(data, sensor, hits, reach, verdict) and n > 0
    assert sorted(out[n:n_all].tolist()) == sorted(naive.occupied_cells(data, hits, verdict))
    assert n_all > n


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_flag_hit_surfaces_kernel_against_reference(seed):
    data, sensor, r, hits, verdict = _evaluator_input(seed)
    some = np.argwhere(data != FREE)[:len(hits):3]    # some hits on occupied or unknown cells
    hits[:len(some)] = some[:, ::-1] + 0.5
    marks = np.zeros((data.size + 7) // 8, np.uint8)
    out = np.zeros(5000, np.int32)
    out[:3] = (7, 8, 9)                                  # flags of the evaluator before it
    n = K.flag_hit_surfaces(data, hits, verdict, marks, out, 3)
    expect = naive.hit_surface_cells(data, hits, verdict)
    assert out[:3].tolist() == [7, 8, 9] and n - 3 == len(expect) > 0
    assert set(out[3:n].tolist()) == expect
    assert sorted(np.flatnonzero(np.unpackbits(marks, bitorder="little"))) == sorted(expect)
    # cells the unchanged-cells evaluator flagged already (marked) get no second flag
    n_again = K.flag_hit_surfaces(data, hits, verdict, marks, out, n)
    assert n_again == n


@pytest.mark.parametrize("r", [0.5, 5.0, 10.0, 15.0])
def test_new_obstacle_flag_flips_exactly_at_the_new_obstacle_radius(r):
    data = np.zeros((30, 340), np.int8)
    data[21, 320] = OCC                 # the only occupied cell, y in [21, 22)
    _, tol, _ = steps.beam_distances(np.array([r]), 0.05, UpdaterConfig())
    for factor, flagged in ((1 - 1e-6, False), (1 + 1e-6, True)):
        hit = np.array([[320.5, 21.0 - factor * new_obstacle_radius(r) / 0.05]])
        out = np.zeros(2, np.int32)
        n = K.flag_new_obstacles(data, hit, tol, np.array([K.CHANGE], np.int8),
                                 np.zeros((data.size + 7) // 8, np.uint8), out, 0)
        hit_cell = math.floor(hit[0, 1]) * 340 + 320
        assert out[:n].tolist() == ([hit_cell] if flagged else []), (r, factor)


def test_a_new_obstacle_radius_of_0_flags_no_hit_off_the_map():
    """With tol 0 no cell meets the disc around the hit, the map's outside neither: a hit off
    the map is no cell to flag, and its mark would lie outside the bit plane."""
    data = np.zeros((16, 16), np.int8)
    hits = np.array([[20.5, 3.5], [3.5, -0.5], [5.5, 5.5]])
    marks = np.zeros(33, np.uint8)          # one byte more than the map's 32
    out = np.zeros(4, np.int32)
    verdict = np.full(3, K.CHANGE, np.int8)
    n = K.flag_new_obstacles(data, hits, np.zeros(3), verdict, marks, out, 0)
    assert out[:n].tolist() == [5 * 16 + 5]
    assert marks[32] == 0 and np.count_nonzero(np.unpackbits(marks)) == 1


@pytest.mark.parametrize("r", [1.0, 5.0, 10.0, 15.0])
def test_removed_obstacle_walk_ends_exactly_at_p_th(r):
    data = np.zeros((10, 340), np.int8)
    data[5, 300] = OCC                  # on the beam, x in [300, 301)
    _, _, skip = steps.beam_distances(np.array([r]), 0.05, UpdaterConfig())
    for factor, flagged in ((1 - 1e-6, False), (1 + 1e-6, True)):
        # p_th = the hit less the skip: just inside the occupied cell (its last cell, left
        # out), or just past it
        hit = np.array([[301.0 + factor * removed_skip(r) / 0.05, 5.5]])
        sensor = np.array([hit[0, 0] - r / 0.05, 5.5, 0.0])
        cells, _, _, _ = walks(data, sensor, hit, np.array([K.CHANGE], np.int8),
                               1.0 - skip / r, np.zeros(1), cap=1000)
        assert (5 * 340 + 300 in cells) == flagged, (r, factor)


# --- a room scene -----------------------------------------------------------------------------
SOLID = world.Rect(3.0125, 3.0125, 4.0125, 3.6125)     # in M; in the world 0.12 m further north
HOLLOW = world.Rect(6.5125, 2.5125, 8.0125, 3.5125)    # in M, outline only; gone from the world


def room_scene(seed):
    """M: the room with SOLID and HOLLOW (its interior unknown: an enclosed region). One
    720-beam scan of the world from a seeded random pose north of the boxes, a seeded random
    tenth of its beams replaced by random ranges and a few by NaN. Returns (M's cells, scan,
    sensor (gx, gy, yaw))."""
    rng = np.random.default_rng(seed)
    walls = world.room_walls()
    ref = world.rasterise(walls + [SOLID], hollow=[HOLLOW])
    moved = world.Rect(SOLID.x0, SOLID.y0 + 0.12, SOLID.x1, SOLID.y1 + 0.12)
    pose = Pose2D(rng.uniform(2.0, 9.0), rng.uniform(5.0, 9.0), rng.uniform(-math.pi, math.pi))
    scan = world.full_scan(walls + [moved], pose, 0.0)
    ranges = scan.ranges.copy()
    pick = rng.random(ranges.size)
    ranges[pick < 0.1] = rng.uniform(0.1, 8.0, (pick < 0.1).sum())
    ranges[pick > 0.98] = np.nan
    scan = Scan(ranges, scan.angle_min, scan.angle_increment, scan.range_min, scan.range_max)
    return ref.data, scan, steps.to_grid(pose, ref.origin, ref.resolution)


# --- buffers and decision ---------------------------------------------------------------------
def rule(few, support, shift, mask=0x3FF, threshold=7):
    """A ``SETTINGS`` record holding the decision rule's parameters (the others 0)."""
    out = np.zeros(1, SETTINGS)
    out["buffer_mask"], out["threshold"], out["unanimous_min"] = mask, threshold, few
    out["support_mode"], out["count_shift"], out["settled_bound"] = \
        int(support), shift, K.NEVER_SETTLED
    return out


def rule_config(few, support):
    """The same rule as an ``UpdaterConfig`` (N_b 10, T 7), for the plain decision."""
    return UpdaterConfig(unanimous_min=few, neighbour_support=bool(support),
                         support_exact_state=support == 2)


def buffers(hist, seen, decided, ch_marks, un_marks):
    """``Buffers`` without hit buffers (the growth into the unknown off)."""
    return Buffers(hist, seen, decided, ch_marks, un_marks, np.zeros(0, np.uint8),
                   np.zeros(0, np.uint8), np.full((0, 0), -1, np.int32),
                   np.zeros((0, 4096), np.uint16), np.zeros(1, np.int64))


def test_push_flags_against_reference():
    rng = np.random.default_rng(6)
    hist = rng.integers(0, 1024, 500).astype(np.uint16)
    hist[rng.random(500) < 0.5] = 0
    before = hist.copy()
    changed = rng.choice(500, 80, replace=False).astype(np.int32)
    unchanged = rng.choice(500, 200, replace=False).astype(np.int32)
    ch_marks, un_marks = np.full(63, 255, np.uint8), np.full(63, 255, np.uint8)
    moved = np.zeros(280, np.int32)
    seen = np.zeros(500, np.uint8)
    n = K.push_flags(hist, seen, np.zeros(500, np.int8), changed, unchanged, 0x3FF, 7, 0,
                     ch_marks, un_marks, moved)
    flags = np.bincount(np.concatenate([changed, unchanged]), minlength=500)
    assert (seen == flags).all()
    expect = before.astype(int)
    log = []
    for idx, flag in [(i, 1) for i in changed] + [(i, 0) for i in unchanged]:
        old = expect[idx]
        expect[idx] = ((old << 1) | flag) & 0x3FF
        p0, p1 = ref_popcount(old), ref_popcount(expect[idx])
        if p0 != p1:
            log.append(-1 - idx if (p0 >= 7) != (p1 >= 7) else idx)
    assert hist.tolist() == expect.tolist()
    assert moved[:n].tolist() == log
    # the flagged cells' marks cleared (the changed flags' bit by bit, the others kept)
    ch_bits = np.unpackbits(ch_marks, bitorder="little")[:500]
    assert not ch_bits[changed].any() and ch_bits.sum() == 500 - changed.size
    assert not un_marks[unchanged >> 3].any()


@pytest.mark.parametrize("packed", [False, True])
def test_push_flags_keeps_the_marks_of_the_settled_free_cells(packed):
    """With ``full``, the unchanged-flag marks after a push are set on exactly the free cells
    whose flags are all unchanged and (when counted) whose count reached T: those an unchanged
    flag would not change. The buffers are as without it. (Which flags the walks then make:
    ``test_updater_speedup``.)"""
    rng = np.random.default_rng(8)
    size, mask, threshold, shift = 600, 0x3FF, 7, 10 if packed else 0
    data = np.where(rng.random(size) < 0.2, OCC, FREE).astype(np.int8)
    hist = rng.integers(0, 4, size).astype(np.uint16)      # a few flags, mostly none
    hist[rng.random(size) < 0.6] = 0
    if packed:
        hist |= (rng.integers(0, 12, size) << shift).astype(np.uint16)
    full = threshold << shift if packed else 0
    un_marks = np.zeros(75, np.uint8)
    K.settled_marks(data, hist, mask, full, un_marks)
    plain = hist.copy()
    for scan in range(6):
        changed = rng.choice(size, 30, replace=False).astype(np.int32)
        unchanged = rng.choice(size, 200, replace=False).astype(np.int32)
        args = (changed, unchanged, mask, threshold, 3 if packed else 0)
        ch_marks = np.zeros(75, np.uint8)
        ch_marks[changed >> 3] = 255
        un_marks[unchanged >> 3] |= np.uint8(1) << (unchanged & 7).astype(np.uint8)
        moved = np.zeros(230, np.int32)
        seen = np.zeros(0, np.uint8)
        K.push_flags(hist, seen, data, *args, ch_marks, un_marks, moved, shift, full)
        K.push_flags(plain, seen, data, *args, np.zeros(75, np.uint8), np.zeros(75, np.uint8),
                     moved.copy(), shift)
        assert hist.tolist() == plain.tolist()
        counts = (hist >> shift) if packed else np.full(size, threshold)
        expect = (data == FREE) & ((hist & mask) == 0) & (counts >= threshold)
        assert np.unpackbits(un_marks, bitorder="little")[:size].tolist() == expect.tolist()
        assert 0 < expect.sum() < (data == FREE).sum()


@pytest.mark.parametrize("support", [False, True, 2])
@pytest.mark.parametrize("few", [0, 3])
@pytest.mark.parametrize("packed", [False, True])
@pytest.mark.parametrize("skip", [False, True])
def test_decide_incremental_equals_full_map(support, few, packed, skip):
    """Both layouts of the flag counts: an array of their own, and the bits above the flags
    (``shift``); with ``skip``, the push leaves out the cells whose flag agrees with their
    decided bit (some cells get a changed and an unchanged flag in the same scan)."""
    rng = np.random.default_rng(7 + support + 10 * few)
    data = random_map(rng, h=30, w=30, p_occ=0.3, p_unk=0.1)
    flat = data.reshape(-1)
    hist = np.zeros(data.size, np.uint16)
    shift = 10 if packed else 0
    seen = np.zeros(0 if packed else data.size, np.uint8)
    decided = np.zeros((data.size + 7) // 8, np.uint8)
    marks = np.zeros_like(decided), np.zeros_like(decided)
    moved = np.zeros(2000, np.int32)
    count = peak = left_out = 0
    centres = rng.integers(0, 26, (3, 2))
    for scan in range(40):
        # flags in a few blobs, so that neighbours reach the threshold together
        r0, c0 = centres[scan % 3]
        cells = ((r0 + rng.integers(0, 5, 60)) * 30 + c0 + rng.integers(0, 5, 60))
        cells = np.unique(cells).astype(np.int32)
        p = 0.85 if scan < 25 else 0.3
        ch = cells[rng.random(cells.size) < p]
        un = cells[rng.random(cells.size) < 0.3]
        if skip:
            # the cells whose flags agree with their decided bits left out of the decision
            # (counted on copies), in the kernel that pushes and decides
            kept = [a.copy() for a in (hist, seen, decided)]
            n_all = K.push_flags(*kept[:2], flat, ch, un, 0x3FF, 7, few,
                                 *[m.copy() for m in marks], moved, shift=shift)
            left_out += n_all - K.push_flags(hist.copy(), seen.copy(), flat, ch, un, 0x3FF, 7,
                                             few, *[m.copy() for m in marks], moved,
                                             shift=shift, decided=kept[2])
            count += K.push_and_decide(buffers(hist, seen, decided, *marks), flat, 30, ch, un,
                                       moved, rule(few, support, shift))
            assert (kept[0] == hist).all() and (kept[1] == seen).all()   # the same buffers
            # the changed-flag marks left on the cells full of changes, and on those alone
            full = (hist & 0x3FF) == 0x3FF
            assert (np.unpackbits(marks[0], bitorder="little")[:900] == full).all()
        else:
            n = K.push_flags(hist, seen, flat, ch, un, 0x3FF, 7, few, *marks, moved,
                             shift=shift)
            count += K.decide(hist, seen, flat, decided, moved[:n], 30, 0x3FF, 7, few,
                              support, shift=shift)
        counts = hist >> 10 if packed else seen
        expect = naive.decide_all(hist, counts.astype(int), data, rule_config(few, support))
        got = np.unpackbits(decided, bitorder="little")[:900].reshape(30, 30).astype(bool)
        assert (got == expect).all() and count == expect.sum()
        peak = max(peak, count)
    assert peak > count > 0           # cells changed, and some changed back
    assert left_out > 0 or not skip
    full = np.zeros_like(decided)
    assert K.decide_all(hist, seen, flat, full, 30, 0x3FF, 7, few, support, shift=shift) == count
    assert (full == decided).all()


def test_neighbour_support_rule():
    # A free cell with n = 4 and three free 8-neighbours at n >= 7 reaches 4 + 3 = 7.
    data = np.zeros((5, 5), np.int8)
    hist = np.zeros(25, np.uint16)
    hist[12] = 0b1111
    for j in (6, 7, 8):
        hist[j] = 0b1111111
    decided = np.zeros(4, np.uint8)
    seen = np.full(25, 255, np.uint8)
    assert K.decide_cell(hist, seen, data.reshape(-1), decided, 12, 5, 0x3FF, 7, 0, True) == 1
    data[1, 1] = OCC         # one supporter of another state in M: 4 + 2 < 7
    decided[:] = 0
    assert K.decide_cell(hist, seen, data.reshape(-1), decided, 12, 5, 0x3FF, 7, 0, True) == 0
    assert K.decide_cell(hist, seen, data.reshape(-1), decided, 12, 5, 0x3FF, 7, 0, False) == 0


def test_unknown_cells_support_an_occupied_one_only_in_the_two_states():
    # An occupied cell with n = 4 and three unknown 8-neighbours at n >= 7 (seen through as the
    # map grows): 4 + 3 = 7 in the paper's two states, 4 with the same value of M (support 2).
    data = np.full((5, 5), -1, np.int8)
    data[2, 2] = OCC
    hist = np.zeros(25, np.uint16)
    hist[12] = 0b1111
    for j in (6, 7, 8):
        hist[j] = 0b1111111
    seen = np.full(25, 255, np.uint8)
    for support, want in ((1, 1), (2, 0)):
        decided = np.zeros(4, np.uint8)
        assert K.decide_cell(hist, seen, data.reshape(-1), decided, 12, 5, 0x3FF, 7, 0,
                             support) == want
    data[1, 1:4] = OCC       # occupied neighbours support it either way
    decided = np.zeros(4, np.uint8)
    assert K.decide_cell(hist, seen, data.reshape(-1), decided, 12, 5, 0x3FF, 7, 0, 2) == 1


def test_unanimous_rule_for_few_observations():
    # A cell flagged changed by each of the 4 scans that saw it changes with unanimous_min 3 or
    # 4, not 5; one unchanged flag among its 5 undoes it; at 7 flags the threshold rules.
    data = np.zeros((3, 3), np.int8)
    flat = data.reshape(-1)

    def decide(bits, n_seen, few):
        hist = np.zeros(9, np.uint16)
        hist[4] = bits
        seen = np.zeros(9, np.uint8)
        seen[4] = n_seen
        return K.decide_cell(hist, seen, flat, np.zeros(2, np.uint8), 4, 3, 0x3FF, 7, few,
                             False)

    assert decide(0b1111, 4, 3) == 1 and decide(0b1111, 4, 4) == 1
    assert decide(0b1111, 4, 5) == 0 and decide(0b1111, 4, 0) == 0
    assert decide(0b11110, 5, 3) == 0
    assert decide(0b1111110, 7, 3) == 0 and decide(0b1111111, 7, 0) == 1
    data[1, 1] = UNK         # an unknown cell of M seen through by every scan: the same
    assert decide(0b1111, 4, 3) == 1


def test_unanimous_rule_keeps_a_grazed_cell_of_a_surface_the_scans_still_hit():
    # a wall row of M; its middle cell seen through by 4 scans and never hit
    data = np.zeros((3, 3), np.int8)
    data[1, :] = OCC
    flat = data.reshape(-1)
    hist = np.zeros(9, np.uint16)
    seen = np.zeros(9, np.uint8)
    hist[4], seen[4] = 0b1111, 4
    assert K.decide_cell(hist, seen, flat, np.zeros(2, np.uint8), 4, 3, 0x3FF, 7, 3, False) == 1
    seen[3] = 5              # its neighbour was hit by 5 scans (unchanged flags): the wall is
    assert K.decide_cell(hist, seen, flat, np.zeros(2, np.uint8), 4, 3, 0x3FF, 7, 3, False) == 0
    hist[3] = 0b11111        # ... unless every flag of the neighbour said changed too: a box
    assert K.decide_cell(hist, seen, flat, np.zeros(2, np.uint8), 4, 3, 0x3FF, 7, 3, False) == 1


# --- output and last check --------------------------------------------------------------------
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_enclosed_unknown_against_bfs(seed):
    from updater.steps import enclosed_unknown

    rng = np.random.default_rng(seed)
    data = random_map(rng, h=45, w=38, p_occ=0.3, p_unk=0.35)
    for max_cells in (3, 20, 10**6):
        bits, marked = enclosed_unknown(data, max_cells)
        got = np.unpackbits(bits, bitorder="little")[:data.size].reshape(data.shape).astype(bool)
        expect = naive.enclosed_regions(data, max_cells)
        assert (got == expect).all() and marked == expect.sum()
    assert expect.any()


def test_enclosed_unknown_diagonal_leak_is_not_enclosed():
    data = np.zeros((7, 7), np.int8)
    data[1:6, 1:6] = OCC
    data[2:5, 2:5] = UNK                 # a sealed interior
    from updater.steps import enclosed_unknown

    bits, marked = enclosed_unknown(data, 100)
    assert marked == 9
    data[0, 0] = UNK                     # unknown at the border ...
    data[1, 1] = UNK                     # ... touching the interior only through corners
    bits, marked = enclosed_unknown(data, 100)
    assert marked == 0


@pytest.mark.parametrize("close", [False, True])
def test_apply_changes_against_reference(close):
    rng = np.random.default_rng(8)
    data = random_map(rng, h=33, w=41, p_occ=0.2, p_unk=0.3)
    decided = rng.random(data.shape) < 0.1
    enclosed = (data == UNK) & (rng.random(data.shape) < 0.7)
    pack = lambda m: np.packbits(m.reshape(-1), bitorder="little")  # noqa: E731
    out = data.reshape(-1).copy()
    closed = K.apply_changes(data.reshape(-1), pack(decided), pack(enclosed), 41, close,
                             np.zeros(0, np.uint16), out)
    expect = naive.output_map(data, decided, enclosed, UpdaterConfig(last_check=close))
    assert (out.reshape(data.shape) == expect).all()
    assert closed == ((expect == OCC) & (data == UNK) & ~decided).sum()
    assert closed > 0 if close else closed == 0


def test_a_workspace_kept_across_layouts_and_configurations_classifies_as_a_fresh_one():
    # the workspace keeps what a scan's layout and the configuration fix (Workspace.layout,
    # settings, the views of the measured beams' virtual beams): each scan must
    # come out as it does from a workspace that has seen nothing before
    data, scan, sensor = room_scene(2)
    half = Scan(scan.ranges[::2].copy(), scan.angle_min, 2 * scan.angle_increment,
                scan.range_min, scan.range_max)
    part = Scan(scan.ranges[:300].copy(), scan.angle_min, scan.angle_increment,
                scan.range_min, 4.0)
    plain, wide = UpdaterConfig(), UpdaterConfig(window_deg=8.0, virtual_to_measured_ratio=2)
    kept, changes = steps.Workspace(), []
    fields = ("hits", "pairing", "tol", "free_reach", "verdict", "own_expected", "own_found",
              "own_direction", "change")
    for s, cfg in ((scan, plain), (half, plain), (part, plain), (part, wide), (scan, wide),
                   (scan, plain), (half, wide)):
        got = steps.classify_beams(data, s, sensor, 0.05, cfg, kept)
        fresh_ws = steps.Workspace()
        want = steps.classify_beams(data, s, sensor, 0.05, cfg, fresh_ws)
        assert (got.valid, got.raw_changes, got.changes, got.wrap) == \
            (want.valid, want.raw_changes, want.changes, want.wrap)
        for name in fields:
            a, b = getattr(got, name), getattr(want, name)
            assert a.shape == b.shape and np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), \
                name
        # the settings hold the buffers' rules too; their distances' parameters are an array
        assert kept.settings(cfg, 0.05) == fresh_ws.settings(cfg, 0.05)
        assert np.array_equal(kept.settings(cfg, 0.05).dist, fresh_ws.settings(cfg, 0.05).dist)
        assert got.own_expected.shape == (s.beams, 2)
        changes.append(got.changes)
    assert min(changes[:2]) > 0 and not part.covers_full_circle()
