"""The localiser's fused kernels against plain NumPy / Python written from their definitions,
on seeded random inputs, and the whole filter against what the code before them gave on the
same tour, recorded in ``tests/data/golden/localization_filter_case*.npz``
(tests/data/golden/README.md): the same particles and estimates, bit for bit."""

import math

import numpy as np
import pytest

from gridmap import FREE, OCCUPIED, OccupancyGrid, Pose2D, Scan
from localization import LocalizerConfig, MonteCarloLocalizer
from localization import _kernels as k
from localization.estimate import estimate, weighted_mean_cov
from localization.resample import KldParameters, Scratch, kld_resample, resample_indices
from localization.sensor import LikelihoodField, select_beams
from tests.data.golden import golden

import synthetic_warehouse as syn

BIN = np.array([0.5, 0.5, math.radians(10)])
N_THETA = 36


def np_wrap(a):
    return (np.asarray(a, np.float64) + math.pi) % (2 * math.pi) - math.pi


def random_grid(rng, h=37, w=53):
    data = np.where(rng.random((h, w)) < 0.15, OCCUPIED, FREE).astype(np.int8)
    return OccupancyGrid(data, 0.05, (-0.4, -0.3))


# --- likelihood field ----------------------------------------------------------------------
def reference_scores(poses, mount, beams, table, frame, off_value, base):
    """base + the table's value at each beam's end point, beams added in order."""
    ox, oy, res = frame
    out = np.full(poses.shape[0], base, np.float64)
    for i, (x, y, th) in enumerate(poses):
        c, s = math.cos(th), math.sin(th)
        cm, sm = math.cos(mount[2]), math.sin(mount[2])
        sx, sy = x + c * mount[0] - s * mount[1], y + s * mount[0] + c * mount[1]
        cs, ss = c * cm - s * sm, s * cm + c * sm
        for bx, by in beams:
            gx = (sx + cs * bx - ss * by - ox) * (1.0 / res)
            gy = (sy + ss * bx + cs * by - oy) * (1.0 / res)
            inside = 0 <= gx < table.shape[1] and 0 <= gy < table.shape[0]
            out[i] += float(table[int(gy), int(gx)]) if inside else off_value
    return out


@pytest.mark.parametrize("seed, n", [(0, 1), (1, 255), (2, 256), (3, 600)])
def test_blocked_likelihood_field_equals_the_beam_by_beam_sum(seed, n):
    rng = np.random.default_rng(seed)
    grid = random_grid(rng)
    lf = LikelihoodField(grid, 0.5, 0.9, 0.1, 0.1)
    table, off_value, base = lf.table(8.0)
    # particles on, near and well off the map, so end points leave it on every side
    poses = np.column_stack((rng.uniform(-1.5, 4.0, n), rng.uniform(-1.5, 3.0, n),
                             rng.uniform(-4, 4, n)))
    beams = rng.uniform(-2.0, 2.0, (45, 2))
    mount = np.array([0.2, -0.05, 0.3])
    got = np.empty(n)
    k.likelihood_field(poses, mount, beams, table, lf.frame, off_value, base, got)
    want = reference_scores(poses, mount, beams, table, lf.frame, off_value, base)
    np.testing.assert_allclose(got, want, rtol=1e-14, atol=0)


# --- wrap, bins, clusters ------------------------------------------------------------------
def test_wrap_equals_numpy_remainder_everywhere():
    rng = np.random.default_rng(4)
    edge = [math.pi, -math.pi, 0.0, -0.0, 2 * math.pi, -2 * math.pi, 3 * math.pi,
            np.nextafter(math.pi, 0), np.nextafter(-math.pi, 0), 1e300, -1e-300, 7e-17]
    a = np.concatenate((rng.uniform(-20, 20, 20000), edge))
    got = np.array([k.wrap(x) for x in a])
    want = np_wrap(a)
    assert np.array_equal(got, want) and np.array_equal(np.signbit(got), np.signbit(want))


def reference_keys(poses):
    ix = np.clip(np.floor(poses[:, 0] / BIN[0]), -k.KEY_OFFSET, k.KEY_OFFSET - 1).astype(np.int64)
    iy = np.clip(np.floor(poses[:, 1] / BIN[1]), -k.KEY_OFFSET, k.KEY_OFFSET - 1).astype(np.int64)
    it = np.minimum(((np_wrap(poses[:, 2]) + math.pi) / BIN[2]).astype(np.int64), N_THETA - 1)
    return ((ix + k.KEY_OFFSET) * k.KEY_SPAN + (iy + k.KEY_OFFSET)) * N_THETA + it


def reference_clusters(poses):
    """Labels by flood fill over touching bins (26-neighbours, heading wrapping), numbered in
    the order of each cluster's least bin key."""
    keys = reference_keys(poses)
    cells = {int(key): (int(key) // N_THETA // k.KEY_SPAN, int(key) // N_THETA % k.KEY_SPAN,
                        int(key) % N_THETA) for key in np.unique(keys)}
    index = {v: key for key, v in cells.items()}
    group = {}
    for start in sorted(cells):
        if start in group:
            continue
        group[start], todo = start, [start]
        while todo:
            x, y, t = cells[todo.pop()]
            for dx in (-1, 0, 1):
                for dy in (-1, 0, 1):
                    for dt in (-1, 0, 1):
                        other = index.get((x + dx, y + dy, (t + dt) % N_THETA))
                        if other is not None and other not in group:
                            group[other] = start
                            todo.append(other)
    order = {g: i for i, g in enumerate(sorted(set(group.values())))}
    return np.array([order[group[int(key)]] for key in keys])


def cloud(rng, n, spots):
    """Particles around a few spots, two of them across the +-pi heading seam."""
    centres = rng.uniform(-3, 3, (spots, 3))
    centres[: min(2, spots), 2] = [math.pi - 0.01, -math.pi + 0.02][: min(2, spots)]
    pick = rng.integers(spots, size=n)
    return centres[pick] + rng.normal(0, [0.3, 0.3, 0.1], (n, 3))


@pytest.mark.parametrize("seed, n, spots", [(0, 1, 1), (1, 50, 3), (2, 3000, 6), (3, 2000, 40)])
def test_cluster_particles_match_a_flood_fill(seed, n, spots):
    rng = np.random.default_rng(seed)
    poses = cloud(rng, n, spots)
    weights = rng.random(n)
    labels = np.empty(n, np.int64)
    scratch = Scratch()
    share, counts = k.cluster_particles(poses, weights, BIN, N_THETA, scratch.table(n), labels)
    want = reference_clusters(poses)
    assert np.array_equal(labels, want)
    assert np.array_equal(counts, np.bincount(want))
    np.testing.assert_allclose(share, [weights[want == c].sum() for c in range(counts.size)],
                               rtol=1e-12)
    assert np.all(scratch.table(n) == -1)                # left empty for the next call


def test_estimate_is_the_heaviest_cluster_mean_and_covariance():
    rng = np.random.default_rng(5)
    poses = cloud(rng, 4000, 5)
    weights = rng.random(4000) ** 4
    mean, cov, share = estimate(poses, weights, KldParameters(10, 4000, 0.05, 0.99, BIN))
    labels = reference_clusters(poses)
    sums = np.array([weights[labels == c].sum() for c in range(labels.max() + 1)])
    sel = labels == np.argmax(sums)
    w = weights[sel] / weights[sel].sum()
    p = poses[sel]
    want_mean = np.array([w @ p[:, 0], w @ p[:, 1],
                          math.atan2(w @ np.sin(p[:, 2]), w @ np.cos(p[:, 2]))])
    d = p - want_mean
    d[:, 2] = np_wrap(d[:, 2])
    np.testing.assert_allclose(mean, want_mean, rtol=0, atol=1e-12)
    np.testing.assert_allclose(cov, np.einsum("i,ij,ik->jk", w, d, d), rtol=1e-10, atol=1e-15)
    assert share == pytest.approx(sums.max() / sums.sum(), rel=1e-12)


def test_centred_deviations_equal_numpy():
    rng = np.random.default_rng(6)
    poses = rng.uniform(-4, 4, (999, 3))
    mean, w = np.array([0.3, -0.2, 3.1]), rng.random(999)
    d, dw = np.empty_like(poses), np.empty_like(poses)
    k.centred(poses, mean, w, d, dw)
    want = poses - mean
    want[:, 2] = np_wrap(want[:, 2])
    assert np.array_equal(d, want) and np.array_equal(dw, want * w[:, None])
    _, cov = weighted_mean_cov(poses, w)
    assert np.allclose(cov, cov.T)


# --- resampling ----------------------------------------------------------------------------
@pytest.mark.parametrize("seed, n, count", [(0, 1, 1), (1, 10, 37), (2, 5000, 5000),
                                            (3, 700, 50)])
def test_systematic_walk_equals_searchsorted(seed, n, count):
    rng = np.random.default_rng(seed)
    w = rng.random(n) ** 3
    cum = np.cumsum(w / w.sum())
    cum[-1] = 1.0
    u = rng.random()
    got = np.empty(count, np.int64)
    assert k.systematic_take(cum, u, count, got)
    assert np.array_equal(got, np.searchsorted(cum, (u + np.arange(count)) / count, "right"))
    if n > 2:                              # a rounded sum above 1 before the end: refused
        cum[-2] = 1.0 + 2e-16
        assert not k.systematic_take(cum, u, count, got)


def reference_kld(keys, err, z, lo, hi):
    """AMCL's loop: keep samples until their count exceeds Fox's bound for the bins seen."""
    seen = set()
    for m, key in enumerate(keys[:hi]):
        seen.add(int(key))
        kk = len(seen)
        bound = hi
        if kk > 1:
            b = 2 / (9 * (kk - 1))
            bound = min(max(math.ceil((kk - 1) / (2 * err) * (1 - b + math.sqrt(b) * z) ** 3),
                            lo), hi)
        if m + 1 > bound:
            return m + 1
    return min(len(keys), hi)


@pytest.mark.parametrize("seed, n, spots, lo", [(0, 2000, 1, 10), (1, 2000, 30, 100),
                                                 (2, 300, 3, 300), (3, 1, 1, 1)])
def test_kld_take_keeps_what_amcl_keeps(seed, n, spots, lo):
    rng = np.random.default_rng(seed)
    poses = cloud(rng, n, spots)
    order = rng.integers(n, size=n)
    out = np.empty((n, 3))
    scratch = Scratch()
    m = k.kld_take(poses, order, BIN, N_THETA, 0.05, 0.99, lo, n, scratch.table(n), out)
    assert m == reference_kld(reference_keys(poses[order]), 0.05, 0.99, lo, n)
    assert np.array_equal(out[:m], poses[order[:m]])
    assert np.all(scratch.table(n) == -1)


@pytest.mark.parametrize("scheme", ["systematic", "stratified", "residual", "multinomial"])
def test_kld_resample_is_the_kept_prefix_of_the_shuffled_draw(scheme):
    rng = np.random.default_rng(7)
    poses = cloud(rng, 3000, 4)
    w = rng.random(3000) ** 2
    kld = KldParameters(100, 3000, 0.05, 0.99, BIN)
    a, b = np.random.default_rng(8), np.random.default_rng(8)
    got = kld_resample(poses, w, kld, a, scheme, scratch=Scratch())
    idx = resample_indices(w, 3000, b, scheme)
    candidates = poses[idx[b.permutation(3000)]]
    m = reference_kld(reference_keys(candidates), 0.05, 0.99, 100, 3000)
    assert np.array_equal(got, candidates[:m])
    assert a.random() == b.random()                     # the same random numbers used


def test_select_beams_angles_are_the_scans():
    rng = np.random.default_rng(9)
    r = rng.uniform(0.1, 9.0, 1081).astype(np.float32)
    r[::7] = np.inf
    scan = Scan(r, -2.35, 4.7 / 1080, 0.1, 8.0)
    beams = select_beams(scan, 60)
    idx = np.unique(np.round(np.linspace(0, 1080, 60)).astype(np.int64))
    ok = np.isfinite(r[idx]) & (r[idx] > 0.1) & (r[idx] < 8.0)
    a, rr = scan.angles()[idx][ok], r[idx][ok].astype(np.float64)
    assert np.array_equal(beams.points, np.column_stack((rr * np.cos(a), rr * np.sin(a))))


# --- the whole filter, against the code before -------------------------------------------
def make_tour():
    """The map, the lidar, the true poses, the odometry and the scans of 90 steps of the
    synthetic warehouse's route (seeded)."""
    layout = syn.warehouse()
    truth, grid = syn.truth_grid(layout), syn.map_grid(layout)
    rng = np.random.default_rng(0)
    poses = syn.route_poses(syn.ROUTE)[:90]
    odom = syn.corrupt_odometry(poses, (0.05, 0.01, 0.05, 0.01), rng)
    lidar = syn.Lidar()
    return grid, lidar, poses, odom, [lidar.scan(truth, p, rng) for p in poses]


def tour_fingerprint(tour) -> str:
    grid, lidar, poses, odom, scans = tour
    return golden.fingerprint(grid.data, grid.resolution, grid.origin, lidar.mount,
                              list(poses), list(odom), scans)


@pytest.fixture(scope="module")
def tour():
    return make_tour()


# (configuration, start) of the runs recorded in localization_filter_case{index}.npz
FILTER_CASES = [
    ({}, "pose"), ({"min_particles": 3000, "max_particles": 3000}, "pose"),
    ({"laser_model_type": "likelihood_field_prob", "resampler": "residual"}, "pose"),
    ({"max_particles": 4000, "recovery_alpha_slow": 0.001, "recovery_alpha_fast": 0.1},
     "global"),
    # odometry that jumps 0.8 m half way: the filter is lost and injects random particles
    ({"recovery_alpha_slow": 0.001, "recovery_alpha_fast": 0.1}, "jump")]


def run_filter(loc, tour, start):
    """Start ``loc`` as ``start`` says and update it with every third scan of the tour:
    yields (what update returned, the estimate) after each update."""
    grid, lidar, poses, odom, scans = tour
    if start == "global":
        loc.initialize_global()
    else:
        loc.initialize(poses[0], np.diag([0.02, 0.02, 0.005]))
    for i in range(0, len(scans), 3):
        o = odom[i]
        if start == "jump" and i >= len(scans) // 2:
            o = Pose2D(o.x + 0.8, o.y, o.theta)
        yield loc.update(o, scans[i], lidar.mount), loc.estimate()


@pytest.mark.parametrize("case", range(len(FILTER_CASES)))
def test_filter_gives_the_same_particles_and_estimates_as_before(tour, case):
    """After every update: what ``update`` returned, the particles and weights (their SHA-256
    digests, of dtype, shape and bytes), the estimate's pose, covariance and cluster weight,
    all as the code before gave them."""
    config, start = FILTER_CASES[case]
    want = golden.Golden(f"localization_filter_case{case}")
    want.check_inputs(tour_fingerprint(tour))
    assert want.facts["case"] == golden.as_recorded([config, start])
    loc = MonteCarloLocalizer(tour[0], LocalizerConfig(**config), seed=11)
    k = -1
    for k, (updated, est) in enumerate(run_filter(loc, tour, start)):
        assert updated == bool(want["updated"][k])
        assert golden.array_digest(loc.particles) == str(want["particles"][k]), f"update {k}"
        assert golden.array_digest(loc.weights) == str(want["weights"][k]), f"update {k}"
        # the estimate's sums are numpy's, handed to the CPU's vector units: their order, and so
        # the last bits, differ between processors (the particles and weights above are
        # compared bit for bit)
        assert np.allclose(est.pose.as_array(), want["pose"][k], rtol=1e-12, atol=1e-12)
        assert np.allclose(est.cov, want["cov"][k], rtol=1e-12, atol=0.0)
        assert math.isclose(est.cluster_weight, want["cluster_weight"][k], rel_tol=1e-12)
    assert k + 1 == len(want["updated"])
