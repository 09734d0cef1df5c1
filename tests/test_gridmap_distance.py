"""The distance field against a brute-force NumPy reference."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gridmap import FREE, OCCUPIED, UNKNOWN, GridError, OccupancyGrid
from gridmap.distance import distance_to_occupied


def brute_force_distance(grid: OccupancyGrid) -> np.ndarray:
    """min over occupied cells of the centre-to-centre distance [m]; inf without any."""
    occ_r, occ_c = np.nonzero(grid.data == OCCUPIED)
    rows, cols = np.indices(grid.shape)
    if occ_r.size == 0:
        return np.full(grid.shape, np.inf)
    d2 = (rows[..., None] - occ_r) ** 2 + (cols[..., None] - occ_c) ** 2
    return np.sqrt(d2.min(axis=-1)) * grid.resolution


def random_grid(rng, h, w, p_occ):
    data = rng.choice([FREE, UNKNOWN], size=(h, w), p=[0.8, 0.2]).astype(np.int8)
    data[rng.random((h, w)) < p_occ] = OCCUPIED
    return OccupancyGrid(data, 0.05, (-1.0, 2.0))


@pytest.mark.parametrize("shape,p_occ", [((1, 1), 1.0), ((1, 17), 0.1), ((23, 1), 0.1),
                                         ((40, 31), 0.01), ((31, 40), 0.2), ((64, 64), 0.002)])
def test_matches_brute_force(shape, p_occ):
    rng = np.random.default_rng(3)
    grid = random_grid(rng, *shape, p_occ)
    grid.data[rng.integers(shape[0]), rng.integers(shape[1])] = OCCUPIED
    got = distance_to_occupied(grid)
    assert got.dtype == np.float32 and got.shape == grid.shape
    np.testing.assert_allclose(got, brute_force_distance(grid), rtol=1e-6, atol=1e-7)


@settings(max_examples=60, deadline=None)
@given(h=st.integers(1, 25), w=st.integers(1, 25), p_occ=st.floats(0.0, 0.5),
       seed=st.integers(0, 2**31 - 1), cap=st.one_of(st.none(), st.floats(0.0, 1.0)))
def test_matches_brute_force_property(h, w, p_occ, seed, cap):
    grid = random_grid(np.random.default_rng(seed), h, w, p_occ)
    want = brute_force_distance(grid)
    if cap is not None:
        want = np.minimum(want, cap)
    got = distance_to_occupied(grid, cap)
    np.testing.assert_allclose(got, want.astype(np.float32), rtol=1e-6, atol=1e-7)


def test_known_values_and_cap():
    data = np.zeros((5, 7), np.int8)
    data[2, 3] = OCCUPIED
    grid = OccupancyGrid(data, 0.1)
    d = distance_to_occupied(grid, max_distance=0.25)
    assert d[2, 3] == 0.0
    assert d[2, 4] == pytest.approx(0.1)
    assert d[3, 4] == pytest.approx(np.sqrt(2) * 0.1)
    assert d[0, 3] == pytest.approx(0.2)
    assert d[0, 0] == pytest.approx(0.25)        # sqrt(13) * 0.1 capped


def test_unknown_cells_are_not_obstacles():
    data = np.full((3, 9), UNKNOWN, np.int8)
    data[1, 0] = OCCUPIED
    d = distance_to_occupied(OccupancyGrid(data, 1.0))
    assert d[1, 8] == pytest.approx(8.0)


def test_no_occupied_cell():
    grid = OccupancyGrid(np.zeros((4, 4), np.int8), 0.05)
    assert np.all(np.isinf(distance_to_occupied(grid)))
    assert np.all(distance_to_occupied(grid, 2.0) == np.float32(2.0))


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), "2"])
def test_bad_cap_is_refused(bad):
    grid = OccupancyGrid(np.zeros((2, 2), np.int8), 0.05)
    with pytest.raises(GridError, match="max_distance"):
        distance_to_occupied(grid, bad)


@settings(max_examples=60, deadline=None)
@given(f=st.lists(st.one_of(st.just(np.inf), st.floats(0.0, 50.0)), min_size=1, max_size=30))
def test_edt_1d_kernel_matches_reference(f):
    from gridmap._distance_kernels import edt_1d

    f = np.array(f, np.float64)
    n = f.size
    out = np.empty(n)
    edt_1d(f, out, np.empty(n, np.int64), np.empty(n + 1))
    q = np.arange(n)
    want = ((q[:, None] - q[None, :]) ** 2 + f[None, :]).min(axis=1)
    np.testing.assert_allclose(out, want, rtol=1e-12)
