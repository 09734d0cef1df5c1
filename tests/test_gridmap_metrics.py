"""Map metrics on grids worked out by hand, and OPDF against a brute-force search."""

import math

import numpy as np
import pytest

from gridmap import FREE, OCCUPIED, UNKNOWN, GridError, OccupancyGrid
from gridmap.metrics import (compare_maps, cross_correlation, map_score, opdf, opdf_one_way,
                             taxicab_distance)

F, O, U = FREE, OCCUPIED, UNKNOWN


def room(n=12):
    """A walled room: free inside, unknown outside the walls, a box in one corner."""
    d = np.full((n, n), U, np.int8)
    d[1:-1, 1:-1] = O
    d[2:-2, 2:-2] = F
    d[3:5, 3:5] = O
    return d


def inverse(d):
    out = d.copy()
    out[d == F] = O
    out[d == O] = F
    return out


def test_identical_maps_score_100():
    a = OccupancyGrid(room(), 0.05)
    assert compare_maps(a, a.copy()) == {"cc": pytest.approx(100.0, abs=1e-12), "ms": 100.0,
                                         "opdf": 100.0}


def test_inverse_map():
    d = room()
    assert cross_correlation(d, inverse(d)) == pytest.approx(-100.0, abs=1e-12)
    # Every cell occupied in either map is free in the other: (1 - 0)^2 = 1 everywhere.
    assert map_score(d, inverse(d)) == pytest.approx(0.0, abs=1e-12)


def test_cc_and_ms_by_hand():
    # m = [0, 1, 0.5, 0], n = [0, 1, 1, 0.5]: <m> = 0.375, <n> = 0.625, <mn> = 0.375,
    # cov = 0.140625, var(m) = var(n) = 0.171875 -> CC = 0.140625 / 0.171875 = 81.82 %.
    m = np.array([[F, O, U, F]], np.int8)
    n = np.array([[F, O, O, U]], np.int8)
    assert cross_correlation(m, n) == pytest.approx(100 * 0.140625 / 0.171875, abs=1e-10)
    # Occupied in either: cells 1 and 2, squared differences 0 and 0.25 -> MS = 87.5 %.
    assert map_score(m, n) == pytest.approx(87.5, abs=1e-12)
    # int arrays of another dtype read the same
    assert map_score(m.astype(np.int32), n.astype(np.int64)) == pytest.approx(87.5, abs=1e-12)


def test_opdf_by_hand():
    a = np.zeros((5, 5), np.int8)
    b = np.zeros((5, 5), np.int8)
    a[0, 0] = a[4, 4] = O
    b[0, 1] = O
    # window (3, 4): r = 5. A->B: d = 1 and |4 - 0| + |4 - 1| = 7 -> 5; 100 (1 - 6 / 10) = 40.
    # B->A: d = 1; 100 (1 - 1 / 5) = 80. OPDF = 60.
    assert opdf_one_way(a, b, window=(3, 4)) == pytest.approx(40.0, abs=1e-12)
    assert opdf_one_way(b, a, window=(3, 4)) == pytest.approx(80.0, abs=1e-12)
    assert opdf(a, b, window=(3, 4)) == pytest.approx(60.0, abs=1e-12)
    # Default window 20 x 20: r = 28.28; A->B = 100 (1 - 8 / 56.57), B->A = 100 (1 - 1 / 28.28).
    r = math.sqrt(800)
    want = 0.5 * (100 * (1 - 8 / (2 * r)) + 100 * (1 - 1 / r))
    assert opdf(a, b) == pytest.approx(want, abs=1e-12)


def test_opdf_empty_maps():
    a = np.zeros((4, 6), np.int8)
    b = a.copy()
    b[1, 2] = O
    assert opdf_one_way(a, b) == 100.0   # A has no occupied cell
    assert opdf_one_way(b, a) == 0.0     # B's cell finds nothing: d = r
    assert opdf(a, b) == 50.0
    assert opdf(a, a) == 100.0


def brute_opdf_one_way(a, b, window):
    r = math.hypot(*window)
    pa, pb = np.argwhere(a == O), np.argwhere(b == O)
    if len(pa) == 0:
        return 100.0
    if len(pb) == 0:
        return 0.0
    d = np.abs(pa[:, None, :] - pb[None, :, :]).sum(axis=2).min(axis=1)
    return 100 * (1 - np.minimum(d, r).sum() / (len(pa) * r))


def test_opdf_matches_brute_force_on_random_grids():
    rng = np.random.default_rng(8)
    for _ in range(200):
        h, w = rng.integers(1, 30, 2)
        density = rng.uniform(0, 0.2)
        a = np.where(rng.random((h, w)) < density, O, rng.choice([F, U], (h, w))).astype(np.int8)
        b = np.where(rng.random((h, w)) < density, O, rng.choice([F, U], (h, w))).astype(np.int8)
        window = tuple(rng.integers(1, 25, 2))
        want = 0.5 * (brute_opdf_one_way(a, b, window) + brute_opdf_one_way(b, a, window))
        assert opdf(a, b, window) == pytest.approx(want, abs=1e-9)


def test_taxicab_distance_matches_numpy_reference():
    rng = np.random.default_rng(9)
    for _ in range(50):
        h, w = rng.integers(1, 40, 2)
        occ = rng.random((h, w)) < rng.uniform(0, 0.1)
        got = taxicab_distance(occ)
        assert got.dtype == np.int32
        if not occ.any():
            assert (got == h + w).all()
            continue
        rr, cc = np.mgrid[0:h, 0:w]
        pts = np.argwhere(occ)
        want = (np.abs(rr[..., None] - pts[:, 0]) + np.abs(cc[..., None] - pts[:, 1])).min(axis=2)
        assert np.array_equal(got, want)


def test_uniform_map_has_no_cross_correlation():
    a = np.zeros((3, 3), np.int8)
    with pytest.raises(GridError, match="first map.*standard deviation 0"):
        cross_correlation(a, room(3))
    with pytest.raises(GridError, match="second map"):
        cross_correlation(room(3), np.full((3, 3), U, np.int8))


def test_maps_that_cannot_be_compared():
    a = OccupancyGrid(room(), 0.05)
    with pytest.raises(GridError, match="different shapes"):
        opdf(a, OccupancyGrid(room(13), 0.05))
    with pytest.raises(GridError, match="different resolutions"):
        map_score(a, OccupancyGrid(room(), 0.1))
    with pytest.raises(GridError, match="different origins"):
        compare_maps(a, OccupancyGrid(room(), 0.05, origin=(0.05, 0.0)))
    with pytest.raises(GridError, match="different shapes"):
        cross_correlation(room(), room(11))
    with pytest.raises(GridError, match="outside -1..100"):
        map_score(np.full((2, 2), 200), np.zeros((2, 2), int))
    with pytest.raises(GridError, match="window"):
        opdf(a, a, window=(0, 20))
