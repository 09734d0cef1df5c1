"""The localiser in a synthetic warehouse (synthetic_warehouse): scans ray-cast in a fine
solid world, a 5 cm SLAM-like map, odometry corrupted with the odometry motion model using the
simulator's noise (alpha1..4 = 0.05, 0.01, 0.05, 0.01)."""

import math

import numpy as np
import pytest

from gridmap import FREE, OccupancyGrid, Pose2D
from localization import LocalizationError, LocalizerConfig, MonteCarloLocalizer
import synthetic_warehouse as syn

ODOM_NOISE = (0.05, 0.01, 0.05, 0.01)
START_COV = np.diag([0.1 ** 2, 0.1 ** 2, 0.05 ** 2])
MOVES = {"pallet_1": (1.0, 1.5), "pallet_2": (-1.0, 2.0), "pallet_3": (2.0, 0.0),
         "pallet_4": (0.0, -2.5), "box_1": (-1.5, -1.0), "drum_1": (1.0, 0.0),
         "drum_2": (1.0, 1.0)}


class World:
    def __init__(self):
        self.layout = syn.warehouse()
        self.truth = syn.truth_grid(self.layout)
        self.map = syn.map_grid(self.layout)
        self.lidar = syn.Lidar()
        self.route = syn.route_poses(syn.ROUTE)

    def drive(self, poses, rng):
        """(true pose, odometry pose, scan) along ``poses``."""
        odom = syn.corrupt_odometry(poses, ODOM_NOISE, rng)
        return [(p, o, self.lidar.scan(self.truth, p, rng, 0.1 * i))
                for i, (p, o) in enumerate(zip(poses, odom))]


@pytest.fixture(scope="module")
def world():
    return World()


@pytest.fixture(scope="module")
def tour(world):
    return world.drive(world.route, np.random.default_rng(1))


def track(grid, tour, lidar, config=None, seed=0, on_update=None):
    """Translation errors [m] of ``pose_at`` at every scan, initialised around the truth."""
    loc = MonteCarloLocalizer(grid, config, seed=seed)
    loc.initialize(tour[0][0], START_COV)
    errors = []
    for i, (truth, odom, scan) in enumerate(tour):
        if loc.update(odom, scan, lidar.mount) and on_update:
            on_update(loc, i)
        est = loc.estimate().pose_at(odom)
        errors.append(math.hypot(est.x - truth.x, est.y - truth.y))
    return np.array(errors), loc


def rmse(errors):
    return float(np.sqrt(np.mean(np.square(errors))))


# --- the four acceptance points, on the synthetic warehouse ----------------------------------
def test_tracking_along_50m_route_rmse_within_5cm(world, tour):
    length = sum(math.dist(a, b) for a, b in zip(syn.ROUTE[:-1], syn.ROUTE[1:]))
    assert length >= 50.0
    for seed in (0, 1):
        errors, loc = track(world.map, tour, world.lidar, seed=seed)
        assert rmse(errors) <= 0.05, f"seed {seed}: RMSE {rmse(errors):.4f} m"
        assert errors.max() < 0.2
        assert loc.config.min_particles <= loc.particle_count <= loc.config.max_particles


def global_run(world, k, config, updates=30):
    rng = np.random.default_rng(100 + k)
    start = int(rng.integers(0, len(world.route) - 500))
    poses = world.route[start:start + 450]
    odom = syn.corrupt_odometry(poses, ODOM_NOISE, rng)
    loc = MonteCarloLocalizer(world.map, config, seed=k)
    loc.initialize_global()
    errors = []
    for truth, o in zip(poses, odom):
        if loc.update(o, world.lidar.scan(world.truth, truth, rng), world.lidar.mount):
            est = loc.estimate().pose
            errors.append(math.hypot(est.x - truth.x, est.y - truth.y))
            if len(errors) == updates:
                break
    return errors


def test_global_localisation_from_10_starts(world):
    # 2000 particles over ~230 m^2 of free space leave under one particle per 0.5 m x 0.5 m x
    # 10 deg bin: global localisation is run with more, as nav2 setups for it do.
    config = LocalizerConfig(max_particles=5000)
    converged = [global_run(world, k, config)[-1] < 0.3 for k in range(10)]
    assert sum(converged) >= 9, converged


def kidnap_run(world, k, config):
    """Track for 120 scans, then jump the robot to a place of the route 5 m away while the
    odometry notices nothing. Returns the number of updates until the estimate is within
    0.3 m again (None if not within 60) and the error 10 updates later."""
    rng = np.random.default_rng(200 + k)
    route = world.route
    i1 = int(rng.integers(0, 300)) + 120
    dist = np.array([math.hypot(p.x - route[i1].x, p.y - route[i1].y) for p in route])
    j0 = int(rng.choice(np.flatnonzero((np.abs(dist - 5.0) < 0.3)
                                       & (np.arange(len(route)) < len(route) - 400))))
    before, after = route[i1 - 120:i1], route[j0:j0 + 400]
    odom_a = syn.corrupt_odometry(before, ODOM_NOISE, rng)
    odom_b = syn.corrupt_odometry(after, ODOM_NOISE, rng)
    odom_b = [odom_a[-1].compose(o.relative_to(odom_b[0])) for o in odom_b]
    loc = MonteCarloLocalizer(world.map, config, seed=k)
    loc.initialize(before[0], START_COV)
    for truth, o in zip(before, odom_a):
        loc.update(o, world.lidar.scan(world.truth, truth, rng), world.lidar.mount)
    errors = []
    for truth, o in zip(after[1:], odom_b[1:]):
        if loc.update(o, world.lidar.scan(world.truth, truth, rng), world.lidar.mount):
            est = loc.estimate().pose
            errors.append(math.hypot(est.x - truth.x, est.y - truth.y))
            if len(errors) == 60:
                break
    found = next((i + 1 for i, e in enumerate(errors) if e < 0.3), None)
    return found, errors


def test_kidnapped_robot_is_found_within_50_updates(world):
    config = LocalizerConfig(recovery_alpha_slow=0.001, recovery_alpha_fast=0.2)
    for k in range(3):
        found, errors = kidnap_run(world, k, config)
        assert found is not None and found <= 50, (k, found)
        assert errors[found - 1 + 5] < 0.3          # and it stays found


def test_without_recovery_the_kidnapped_robot_stays_lost(world):
    found, errors = kidnap_run(world, 0, LocalizerConfig())
    assert found is None and min(errors) > 1.0


def test_moved_objects_make_the_error_larger(world, tour):
    """Measured: RMSE 3.5-3.6 cm on the true map, 4.4-4.8 cm on the stale one."""
    stale = syn.map_grid(world.layout.with_moves(MOVES))
    assert stale.same_frame(world.map)
    for seed in (0, 1):
        true_errors, _ = track(world.map, tour, world.lidar, seed=seed)
        stale_errors, _ = track(stale, tour, world.lidar, seed=seed)
        assert rmse(stale_errors) > 1.15 * rmse(true_errors)
        assert stale_errors.max() > true_errors.max()


# --- map swap, reproducibility, API semantics ----------------------------------------------
def test_set_map_swaps_the_map_live(world, tour):
    """Halfway through the tour the map is swapped for one shifted 0.15 m along x: the filter
    goes on with its particles and follows the new map within a few updates."""
    swap_at, seen = len(tour) // 2, {}
    shifted = OccupancyGrid(world.map.data, world.map.resolution,
                            (world.map.origin[0] + 0.15, world.map.origin[1]))

    def swap(loc, i):
        if i >= swap_at and not seen:
            seen["particles"], seen["estimate"] = loc.particles, loc.estimate()
            loc.set_map(shifted)
            assert loc.grid is shifted
            assert np.array_equal(loc.particles, seen["particles"])
            assert loc.estimate() is seen["estimate"]
    loc = MonteCarloLocalizer(world.map, seed=0, profile="paper")
    loc.initialize(tour[0][0], START_COV)
    offsets = []
    for i, (truth, odom, scan) in enumerate(tour):
        if loc.update(odom, scan, world.lidar.mount):
            swap(loc, i)
        est = loc.estimate().pose_at(odom)
        offsets.append((est.x - truth.x, est.y - truth.y))
    offsets = np.array(offsets)
    assert seen
    before, after = offsets[swap_at - 200:swap_at], offsets[swap_at + 50:]
    assert abs(before[:, 0].mean()) < 0.04
    assert after[:, 0].mean() == pytest.approx(0.15, abs=0.04)
    assert after[:, 0].mean() - before[:, 0].mean() > 0.1
    assert abs(after[:, 1].mean()) < 0.03


def test_same_seed_same_particles_bit_for_bit(world, tour):
    runs = []
    for seed in (5, 5, np.random.SeedSequence(5), 6):
        loc = MonteCarloLocalizer(world.map, seed=seed, profile="paper")
        loc.initialize(tour[0][0], START_COV)
        for truth, odom, scan in tour[:120]:
            loc.update(odom, scan, world.lidar.mount)
        runs.append((loc.particles, loc.weights))
    assert np.array_equal(runs[0][0], runs[1][0]) and np.array_equal(runs[0][1], runs[1][1])
    assert np.array_equal(runs[0][0], runs[2][0])          # int 5 is SeedSequence(5)
    assert not np.array_equal(runs[0][0], runs[3][0])


def test_no_global_random_state_is_touched(world, tour):
    before = np.random.get_state()[1].copy()
    np.random.seed(None)
    state = np.random.get_state()
    loc = MonteCarloLocalizer(world.map, LocalizerConfig(recovery_alpha_slow=0.001,
                                                         recovery_alpha_fast=0.1), seed=1)
    loc.initialize_global()
    for truth, odom, scan in tour[:100]:
        loc.update(odom, scan, world.lidar.mount)
    assert np.array_equal(np.random.get_state()[1], state[1])
    del before


def test_update_schedule_and_map_to_odom(world, tour):
    loc = MonteCarloLocalizer(world.map, seed=0, profile="paper")
    start = tour[0][0]
    loc.initialize(start, START_COV)
    assert loc.estimate().correction_odom == Pose2D(0.0, 0.0, 0.0)
    odom0 = Pose2D(10.0, -3.0, 2.0)                  # odometry has its own frame
    assert loc.update(odom0, tour[0][2], world.lidar.mount) is False       # records odometry
    est = loc.estimate()
    assert est.correction_odom == odom0 and est.correction_pose == start
    # Moving 0.2 m is below update_min_d: no update, the pose follows the odometry.
    odom1 = odom0.compose(Pose2D(0.2, 0.0, 0.0))
    assert loc.update(odom1, tour[0][2], world.lidar.mount) is False
    moved = loc.estimate().pose_at(odom1)
    assert (moved.x, moved.y) == pytest.approx(tuple(start.compose(Pose2D(0.2, 0, 0)).as_array()[:2]))
    # Turning 0.2 rad or moving 0.25 m triggers one.
    assert loc.update(odom1.compose(Pose2D(0, 0, 0.21)), tour[0][2], world.lidar.mount) is True
    est = loc.estimate()
    assert est.correction_odom == odom1.compose(Pose2D(0, 0, 0.21))
    assert est.pose == est.correction_pose
    m2o = est.map_to_odom()
    p = m2o.compose(est.correction_odom)
    assert (p.x, p.y, p.theta) == pytest.approx((est.pose.x, est.pose.y, est.pose.theta))
    assert est.cov.shape == (3, 3) and np.all(np.linalg.eigvalsh(est.cov) >= -1e-12)


def test_initialisation(world):
    loc = MonteCarloLocalizer(world.map, seed=3, profile="paper")
    with pytest.raises(LocalizationError, match="initialize"):
        loc.update(Pose2D(0, 0, 0), syn.Lidar().scan(world.truth, world.route[0],
                                                     np.random.default_rng(0)), Pose2D(0, 0, 0))
    with pytest.raises(LocalizationError, match="estimate"):
        loc.estimate()
    cov = np.array([[0.04, 0.01, 0.0], [0.01, 0.09, 0.0], [0.0, 0.0, 0.01]])
    loc.initialize(Pose2D(1.0, 2.0, 3.1), cov)
    p = loc.particles
    assert p.shape == (2000, 3) and loc.weights.sum() == pytest.approx(1.0)
    d = p - [1.0, 2.0, 3.1]
    d[:, 2] = (d[:, 2] + np.pi) % (2 * np.pi) - np.pi
    np.testing.assert_allclose(np.cov(d.T), cov, atol=0.006)
    loc.initialize_global()
    rows, cols = world.map.world_to_cell(loc.particles[:, 0], loc.particles[:, 1])
    assert np.all(world.map.data[rows, cols] == FREE)
    with pytest.raises(LocalizationError, match="positive semi-definite"):
        loc.initialize(Pose2D(0, 0, 0), -np.eye(3))
    with pytest.raises(LocalizationError, match="config"):
        MonteCarloLocalizer(world.map, config={"alpha1": 0.1})
    with pytest.raises(LocalizationError, match="seed"):
        MonteCarloLocalizer(world.map, seed=1.5, profile="paper")


def test_a_scan_without_valid_beams_leaves_the_weights(world, tour):
    loc = MonteCarloLocalizer(world.map, LocalizerConfig(resample_interval=2), seed=0)
    loc.initialize(tour[0][0], START_COV)
    loc.update(Pose2D(0, 0, 0), tour[0][2], world.lidar.mount)
    empty = syn.Scan(np.full(1081, np.inf, np.float32), -2.3, 0.004, 0.05, 20.0)
    before = loc.weights
    assert loc.update(Pose2D(0.3, 0, 0), empty, world.lidar.mount) is True
    assert np.array_equal(loc.weights, before)           # moved, not reweighted or resampled
    assert loc.update(Pose2D(0.6, 0, 0), tour[5][2], world.lidar.mount) is True
    assert loc.particle_count < len(before)              # the second update resamples
