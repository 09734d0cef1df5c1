"""Every numba kernel of the localiser against a plain NumPy reference, and the resampling
wrapper against filterpy itself."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gridmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid, Pose2D, Scan
from localization import _kernels as k
from localization.config import LocalizationError
from localization.motion import motion_sigmas, odometry_delta, sample_motion
from localization.resample import (KldParameters, Recovery, effective_fraction, histogram_keys,
                                   kld_resample, normalise, resample_indices, temper)
from localization.sensor import LikelihoodField, likelihood_field, select_beams

from filterpy_reference import filterpy_indices


def wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


# --- motion -------------------------------------------------------------------------------
def test_motion_kernel_matches_numpy():
    rng = np.random.default_rng(0)
    poses = rng.uniform(-5, 5, (200, 3))
    delta = np.array([0.3, 0.7, -0.2])
    sigmas = np.array([0.05, 0.1, 0.02])
    noise = rng.standard_normal((200, 3))
    rot1 = delta[0] - sigmas[0] * noise[:, 0]
    trans = delta[1] - sigmas[1] * noise[:, 1]
    rot2 = delta[2] - sigmas[2] * noise[:, 2]
    want = np.column_stack((poses[:, 0] + trans * np.cos(poses[:, 2] + rot1),
                            poses[:, 1] + trans * np.sin(poses[:, 2] + rot1),
                            wrap(poses[:, 2] + rot1 + rot2)))
    got = poses.copy()
    k.sample_motion_odometry(got, delta, sigmas, noise)
    np.testing.assert_allclose(got, want, atol=1e-12)


def test_odometry_delta_round_trip_and_in_place_turn():
    a, b = Pose2D(1.0, 2.0, 0.5), Pose2D(1.5, 2.4, 1.4)
    rot1, trans, rot2 = odometry_delta(a, b)
    x = a.x + trans * math.cos(a.theta + rot1)
    y = a.y + trans * math.sin(a.theta + rot1)
    assert (x, y) == pytest.approx((b.x, b.y))
    assert wrap(a.theta + rot1 + rot2) == pytest.approx(b.theta)
    assert odometry_delta(a, Pose2D(1.0, 2.0, 0.9)) == pytest.approx((0.0, 0.0, 0.4))


def test_backward_motion_is_as_noisy_as_forward():
    fwd = motion_sigmas(odometry_delta(Pose2D(0, 0, 0), Pose2D(0.5, 0, 0)), (0.2,) * 4)
    back = motion_sigmas(odometry_delta(Pose2D(0, 0, 0), Pose2D(-0.5, 0, 0)), (0.2,) * 4)
    np.testing.assert_allclose(fwd, back)


def test_sample_motion_statistics():
    """A 1 m straight step with alpha2 = alpha3 = 0.02: rot1, trans and rot2 each get a std of
    sqrt(0.02) * 1, around (0, 1 m, 0)."""
    rng = np.random.default_rng(1)
    poses = np.zeros((40000, 3))
    sample_motion(poses, Pose2D(0, 0, 0), Pose2D(1.0, 0, 0), (0.0, 0.02, 0.02, 0.0), rng)
    trans = np.hypot(poses[:, 0], poses[:, 1])
    rot1 = np.arctan2(poses[:, 1], poses[:, 0])
    rot2 = wrap(poses[:, 2] - rot1)
    for v, mean in ((rot1, 0.0), (trans, 1.0), (rot2, 0.0)):
        assert np.mean(v) == pytest.approx(mean, abs=0.003)
        assert np.std(v) == pytest.approx(math.sqrt(0.02), rel=0.02)


# --- sensor -------------------------------------------------------------------------------
def small_world():
    data = np.full((40, 60), FREE, np.int8)
    data[0, :] = data[-1, :] = OCCUPIED
    data[:, 0] = data[:, -1] = OCCUPIED
    data[10:20, 30:33] = UNKNOWN
    data[25, 10:20] = OCCUPIED
    return OccupancyGrid(data, 0.05, (-1.0, -0.5))


def reference_likelihood(lf, poses, mount, beams, range_max):
    """Straight from the definition: trig per beam, exp per beam, 1 + sum pz^3 or sum log pz."""
    grid = lf.grid
    out = []
    for x, y, th in poses:
        s = Pose2D(x, y, th).compose(mount)
        r = np.hypot(beams[:, 0], beams[:, 1])
        a = np.arctan2(beams[:, 1], beams[:, 0])
        ex, ey = s.x + r * np.cos(s.theta + a), s.y + r * np.sin(s.theta + a)
        row, col = grid.world_to_cell(ex, ey)
        inside = grid.contains(row, col)
        d = np.full(r.size, lf.max_dist)
        d[inside] = lf.distance[row[inside], col[inside]]
        pz = lf.z_hit * np.exp(-d ** 2 / (2 * lf.sigma_hit ** 2)) + lf.z_rand / range_max
        out.append(math.log(1 + np.sum(pz ** 3)) if lf.model == "likelihood_field"
                   else lf.importance_factor * np.sum(np.log(pz)))
    return np.array(out)


@pytest.mark.parametrize("model", ["likelihood_field", "likelihood_field_prob"])
def test_likelihood_field_kernel_matches_reference(model):
    rng = np.random.default_rng(2)
    grid = small_world()
    lf = LikelihoodField(grid, 2.0, 0.5, 0.5, 0.2, model, 0.3)
    poses = np.column_stack((rng.uniform(-1.5, 2.5, 300), rng.uniform(-1, 2, 300),
                             rng.uniform(-np.pi, np.pi, 300)))
    r = rng.uniform(0.1, 3.0, 45)
    beams = select_beams(Scan(r, -2.0, 4.0 / 44, 0.05, 20.0), 60)
    mount = Pose2D(0.2, -0.05, 0.1)
    got = likelihood_field(lf, poses, mount, beams)
    want = reference_likelihood(lf, poses, mount, beams.points, 20.0)
    np.testing.assert_allclose(got, want, rtol=2e-6, atol=1e-6)


def test_unknown_cells_score_by_distance_and_off_map_as_max_distance():
    grid = small_world()
    lf = LikelihoodField(grid, 2.0, 0.5, 0.5, 0.2, "likelihood_field", 1.0)
    table, off, base = lf.table(20.0)
    assert base == 1.0
    unknown_cell = table[15, 31]                   # inside the unknown block, away from walls
    assert unknown_cell == pytest.approx(float(lf.pz(lf.distance[15, 31], 20.0) ** 3), rel=1e-6)
    assert 0.0 < lf.distance[15, 31] < 2.0
    assert off == pytest.approx(float(lf.pz(2.0, 20.0) ** 3))
    assert off < unknown_cell < table[0, 5]        # on a wall scores best


def test_select_beams_skips_max_range_short_and_non_finite():
    ranges = np.full(100, 5.0, np.float32)
    ranges[::7] = np.inf
    ranges[3::7] = 20.0          # at range_max: a max-range reading
    ranges[5::7] = 0.01          # shorter than range_min
    ranges[6::7] = np.nan
    scan = Scan(ranges, -1.0, 0.02, 0.05, 20.0)
    beams = select_beams(scan, 60)
    idx = np.unique(np.round(np.linspace(0, 99, 60)).astype(int))
    valid = [i for i in idx if i % 7 in (1, 2, 4)]
    assert beams.count == len(valid)
    np.testing.assert_allclose(np.hypot(*beams.points.T), 5.0, rtol=1e-6)
    assert select_beams(scan, 60, max_range=4.0).count == 0
    assert select_beams(scan, 60, max_range=6.0).range_max == 6.0


# --- KLD and clustering --------------------------------------------------------------------
def reference_keys(poses, bin_size, n_theta):
    ix = np.floor(poses[:, 0] / bin_size[0]).astype(np.int64)
    iy = np.floor(poses[:, 1] / bin_size[1]).astype(np.int64)
    it = np.minimum(((wrap(poses[:, 2]) + np.pi) / bin_size[2]).astype(np.int64), n_theta - 1)
    return ix, iy, it


def test_bin_keys_match_numpy():
    rng = np.random.default_rng(3)
    kld = KldParameters(500, 2000, 0.05, 0.99, np.array([0.5, 0.5, math.radians(10)]))
    poses = np.column_stack((rng.uniform(-30, 30, 5000), rng.uniform(-30, 30, 5000),
                             rng.uniform(-7, 7, 5000)))
    keys = histogram_keys(poses, kld)
    ix, iy, it = reference_keys(poses, kld.bin_size, kld.n_theta)
    ref = np.unique(np.column_stack((ix, iy, it)), axis=0)
    assert np.unique(keys).size == ref.shape[0]
    cell = keys // kld.n_theta
    assert np.array_equal(keys % kld.n_theta, it)
    assert np.array_equal(cell // k.KEY_SPAN - k.KEY_OFFSET, ix)
    assert np.array_equal(cell % k.KEY_SPAN - k.KEY_OFFSET, iy)


def reference_limit(kk, err, z, lo, hi):
    if kk <= 1:
        return hi
    b = 2 / (9 * (kk - 1))
    n = math.ceil((kk - 1) / (2 * err) * (1 - b + math.sqrt(b) * z) ** 3)
    return min(max(n, lo), hi)


@pytest.mark.parametrize("kk", [0, 1, 2, 3, 10, 50, 200, 1000])
def test_resample_limit_is_fox_bound(kk):
    assert k.resample_limit(kk, 0.05, 0.99, 500, 2000) == reference_limit(kk, 0.05, 0.99, 500, 2000)
    assert k.resample_limit(kk, 0.01, 3.0, 10, 10**6) == reference_limit(kk, 0.01, 3.0, 10, 10**6)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n_bins=st.integers(1, 400), lo=st.integers(1, 300))
def test_kld_sample_count_matches_reference(seed, n_bins, lo):
    rng = np.random.default_rng(seed)
    keys = rng.integers(0, n_bins, 3000).astype(np.int64) * 7919
    table = np.full(8192, -1, np.int64)
    got = k.kld_sample_count(keys, 0.05, 0.99, lo, 3000, table)
    seen, want = set(), 3000
    for m, key in enumerate(keys):
        seen.add(int(key))
        if m + 1 > reference_limit(len(seen), 0.05, 0.99, lo, 3000):
            want = m + 1
            break
    assert got == want


def reference_clusters(keys, n_theta):
    """Flood fill over occupied bins with 26-neighbours, heading wrapping."""
    cells = {}
    for key in np.unique(keys):
        it, cell = key % n_theta, key // n_theta
        cells[(cell // k.KEY_SPAN, cell % k.KEY_SPAN, it)] = None
    label = 0
    for start in list(cells):
        if cells[start] is not None:
            continue
        stack = [start]
        cells[start] = label
        while stack:
            x, y, t = stack.pop()
            for dx in (-1, 0, 1):
                for dy in (-1, 0, 1):
                    for dt in (-1, 0, 1):
                        nb = (x + dx, y + dy, (t + dt) % n_theta)
                        if nb in cells and cells[nb] is None:
                            cells[nb] = label
                            stack.append(nb)
        label += 1
    out = []
    for key in keys:
        it, cell = key % n_theta, key // n_theta
        out.append(cells[(cell // k.KEY_SPAN, cell % k.KEY_SPAN, it)])
    return np.array(out), label


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(1, 400))
def test_cluster_bins_match_flood_fill(seed, n):
    rng = np.random.default_rng(seed)
    kld = KldParameters(1, 1000, 0.05, 0.99, np.array([0.5, 0.5, math.radians(10)]))
    poses = np.column_stack((rng.uniform(-3, 3, n), rng.uniform(-3, 3, n),
                             rng.uniform(-np.pi, np.pi, n)))
    keys = histogram_keys(poses, kld)
    labels = np.empty(n, np.int64)
    count = k.cluster_bins(keys, kld.n_theta, labels)
    want, want_count = reference_clusters(keys, kld.n_theta)
    assert count == want_count
    # The same partition, whatever the numbering.
    pairs = set(zip(labels.tolist(), want.tolist()))
    assert len(pairs) == count == len({a for a, _ in pairs}) == len({b for _, b in pairs})


def test_clusters_join_across_heading_wrap():
    kld = KldParameters(1, 10, 0.05, 0.99, np.array([0.5, 0.5, math.radians(10)]))
    poses = np.array([[0.1, 0.1, math.pi - 0.01], [0.1, 0.1, -math.pi + 0.01], [5, 5, 0]])
    labels = np.empty(3, np.int64)
    assert k.cluster_bins(histogram_keys(poses, kld), kld.n_theta, labels) == 2
    assert labels[0] == labels[1] != labels[2]


# --- resampling ----------------------------------------------------------------------------
def filterpy_with(monkeypatch, scheme, weights, draws):
    """filterpy's own function fed the given uniform draws instead of the global state."""
    from filterpy.monte_carlo import resampling

    it = iter(draws)
    monkeypatch.setattr(resampling, "random", lambda size=None: next(it))
    return getattr(resampling, f"{scheme}_resample")(weights)


@pytest.mark.parametrize("scheme", ["systematic", "stratified", "multinomial"])
@pytest.mark.parametrize("seed", range(5))
def test_resample_indices_equal_filterpy_fed_the_same_numbers(monkeypatch, scheme, seed):
    w = normalise(np.random.default_rng(seed).gamma(0.3, size=700))
    n = w.size
    draw = np.random.default_rng(100 + seed)
    ours = resample_indices(w, n, np.random.default_rng(100 + seed), scheme)
    draws = [draw.random()] if scheme == "systematic" else [draw.random(n)]
    theirs = filterpy_with(monkeypatch, scheme, w, draws)
    assert np.array_equal(ours, theirs)


@pytest.mark.parametrize("scheme", ["systematic", "stratified", "residual", "multinomial"])
def test_resample_counts_follow_weights(scheme):
    rng = np.random.default_rng(5)
    w = np.array([0.0, 0.5, 0.2, 0.3, 0.0])
    counts = np.zeros(5)
    for _ in range(300):
        counts += np.bincount(resample_indices(w, 1000, rng, scheme), minlength=5)
    np.testing.assert_allclose(counts / counts.sum(), w, atol=0.003)
    assert counts[0] == counts[4] == 0


def test_systematic_count_is_exact_to_one():
    w = normalise(np.random.default_rng(6).random(333))
    idx = resample_indices(w, 2000, np.random.default_rng(0), "systematic")
    assert np.all(np.abs(np.bincount(idx, minlength=333) - 2000 * w) < 1.0 + 1e-9)


def test_normalise_and_degenerate_weights():
    assert normalise([0, 0, 0]) == pytest.approx([1 / 3] * 3)
    assert normalise([1e-300, 3e-300]) == pytest.approx([0.25, 0.75])
    with pytest.raises(LocalizationError):
        normalise([1.0, np.nan])
    with pytest.raises(LocalizationError):
        normalise([1.0, -0.1])


def test_no_global_random_state_is_used_or_changed():
    before = np.random.get_state()[1].copy()
    w = np.random.default_rng(1).random(500)
    a = filterpy_indices(w, np.random.default_rng(9))
    b = filterpy_indices(w, np.random.default_rng(9))
    assert np.array_equal(a, b)
    resample_indices(w, 800, np.random.default_rng(2))
    assert np.array_equal(np.random.get_state()[1], before)


def test_kld_resample_keeps_fewer_particles_for_a_concentrated_cloud():
    rng = np.random.default_rng(4)
    kld = KldParameters(500, 5000, 0.05, 0.99, np.array([0.5, 0.5, math.radians(10)]))
    tight = rng.normal(0, 0.05, (3000, 3))
    wide = np.column_stack((rng.uniform(-10, 10, 3000), rng.uniform(-10, 10, 3000),
                            rng.uniform(-np.pi, np.pi, 3000)))
    w = np.full(3000, 1 / 3000)
    assert kld_resample(tight, w, kld, rng).shape == (501, 3)      # AMCL stops past the limit
    assert kld_resample(wide, w, kld, rng).shape[0] == 5000


def test_tempering_keeps_the_effective_fraction():
    rng = np.random.default_rng(8)
    log_prior = np.full(1000, -math.log(1000))
    log_p = rng.normal(0, 30, 1000)
    beta = temper(log_prior, log_p, 0.05)
    assert 0 < beta < 1
    assert effective_fraction(log_prior + beta * log_p) == pytest.approx(0.05, abs=0.002)
    assert temper(log_prior, 0.001 * log_p, 0.05) == 1.0
    assert temper(log_prior, log_p, 0.0) == 1.0


def test_recovery_injects_only_while_the_likelihood_is_low():
    r = Recovery(0.001, 0.1)
    for _ in range(100):
        r.observe(math.log(5.0))
    assert r.injection_probability() == 0.0
    for _ in range(30):
        r.observe(math.log(1.0))
    assert 0.5 < r.injection_probability() < 0.8
    assert Recovery(0.0, 0.0).injection_probability() == 0.0


def reference_interpolated_fit(residual, frame, poses, mount, points):
    """Plain NumPy: end points in the map, bilinear interpolation between cell centres."""
    ox, oy, res = frame
    h, w = residual.shape
    out = []
    for x, y, th in poses:
        sx = x + math.cos(th) * mount.x - math.sin(th) * mount.y
        sy = y + math.sin(th) * mount.x + math.cos(th) * mount.y
        a = th + mount.theta
        px = sx + math.cos(a) * points[:, 0] - math.sin(a) * points[:, 1]
        py = sy + math.sin(a) * points[:, 0] + math.cos(a) * points[:, 1]
        gx, gy = (px - ox) / res - 0.5, (py - oy) / res - 0.5
        total = 0.0
        for u, v in zip(gx, gy):
            if u < 0 or v < 0 or u > w - 1 or v > h - 1:
                total += 1.0
                continue
            c0, r0 = min(int(u), w - 2), min(int(v), h - 2)
            fx, fy = u - c0, v - r0
            patch = residual[r0:r0 + 2, c0:c0 + 2].astype(np.float64)
            val = np.array([1 - fy, fy]) @ patch @ np.array([1 - fx, fx])
            total += val * val
        out.append(total / len(points))
    return np.array(out)


def test_interpolated_fit_kernel_matches_reference():
    from localization import _kernels

    rng = np.random.default_rng(5)
    grid = small_world()
    residual = np.ascontiguousarray(rng.uniform(0, 1, grid.shape), np.float32)
    frame = np.array([grid.origin[0], grid.origin[1], grid.resolution])
    poses = np.column_stack((rng.uniform(-1.5, 2.5, 100), rng.uniform(-1, 2, 100),
                             rng.uniform(-np.pi, np.pi, 100)))
    beams = select_beams(Scan(rng.uniform(0.1, 3.0, 45), -2.0, 4.0 / 44, 0.05, 20.0), 60)
    mount = Pose2D(0.2, -0.05, 0.1)
    got = np.empty(len(poses))
    _kernels.interpolated_fit(poses, mount.as_array(), beams.points, residual, frame, got)
    want = reference_interpolated_fit(residual, frame, poses, mount, beams.points)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
    assert (want < 1.0).any() and (want > 0.0).all()
