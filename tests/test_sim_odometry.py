"""The odometry motion model: increments, and the drift it predicts over a route."""

import math

import numpy as np
import pytest

from gridmap import Pose2D
from sim.odometry import Odometry, apply_delta, motion_sigmas, noisy_step, odometry_delta


def test_delta_and_apply_are_inverse():
    rng = np.random.default_rng(0)
    for _ in range(100):
        a = Pose2D(*rng.uniform(-5, 5, 2), rng.uniform(-3, 3))
        b = Pose2D(*rng.uniform(-5, 5, 2), rng.uniform(-3, 3))
        c = apply_delta(a, odometry_delta(a, b))
        assert (c.x, c.y) == pytest.approx((b.x, b.y), abs=1e-12)
        assert math.remainder(c.theta - b.theta, 2 * math.pi) == pytest.approx(0, abs=1e-12)


def test_sigmas_follow_the_motion_model():
    a = (0.1, 0.2, 0.3, 0.4)
    s = motion_sigmas((0.5, 2.0, -0.25), a)
    assert s == pytest.approx(np.sqrt([0.1 * 0.25 + 0.2 * 4, 0.3 * 4 + 0.4 * (0.25 + 0.0625),
                                       0.1 * 0.0625 + 0.2 * 4]))
    # reversing (rot1 near pi) is a small turn for the noise, as in AMCL
    assert motion_sigmas((math.pi - 0.1, 1.0, 0.0), a)[0] == pytest.approx(
        math.sqrt(0.1 * 0.01 + 0.2))


def drive(true_poses, alphas, trials, seed):
    """End poses (trials, 3) of the odometry chained along ``true_poses``."""
    rng = np.random.default_rng(seed)
    out = np.empty((trials, 3))
    for k in range(trials):
        odom = Odometry(true_poses[0], alphas, rng)
        for p in true_poses[1:]:
            odom.tick(p)
        out[k] = odom.pose.as_array()
    return out


def test_straight_drive_drifts_as_the_model_predicts():
    # K increments of delta: heading variance 2 K a2 delta^2, along-track K a3 delta^2
    a = (0.05, 0.01, 0.05, 0.01)
    K, delta = 100, 0.03
    poses = [Pose2D(k * delta, 0.0, 0.0) for k in range(K + 1)]
    end = drive(poses, a, 800, seed=1)
    assert np.var(end[:, 2]) == pytest.approx(2 * K * a[1] * delta ** 2, rel=0.15)
    assert np.var(end[:, 0]) == pytest.approx(K * a[2] * delta ** 2, rel=0.15)
    assert abs(np.mean(end[:, 0]) - K * delta) < 0.01


def test_turning_on_the_spot_drifts_as_the_model_predicts():
    a = (0.05, 0.01, 0.05, 0.01)
    K, dth = 60, 0.05
    poses = [Pose2D(0.0, 0.0, k * dth) for k in range(K + 1)]
    end = drive(poses, a, 800, seed=2)
    err = (end[:, 2] - K * dth + np.pi) % (2 * np.pi) - np.pi
    assert np.var(err) == pytest.approx(K * a[0] * dth ** 2, rel=0.15)
    # the translation noise of a turn moves the robot a little, along its heading
    r2 = end[:, 0] ** 2 + end[:, 1] ** 2
    assert np.mean(r2) == pytest.approx(K * a[3] * dth ** 2, rel=0.2)


def test_standing_still_adds_no_noise_and_pose_at_adds_true_motion():
    rng = np.random.default_rng(3)
    start = Pose2D(1.0, 2.0, 0.5)
    odom = Odometry(start, (0.1, 0.1, 0.1, 0.1), rng)
    assert odom.tick(start) == start and odom.pose_at(start) == start
    moved = odom.tick(Pose2D(1.3, 2.1, 0.6))
    assert moved != Pose2D(1.3, 2.1, 0.6)
    later = odom.pose_at(Pose2D(1.3, 2.1, 0.6).compose(Pose2D(0.1, 0.0, 0.0)))
    assert later.relative_to(moved).x == pytest.approx(0.1, abs=1e-12)


def test_noisy_step_without_noise_is_the_true_increment():
    a, b = Pose2D(0.0, 0.0, 0.2), Pose2D(0.5, 0.1, 0.4)
    out = noisy_step(Pose2D(3.0, 3.0, -1.0), a, b, (0.2, 0.2, 0.2, 0.2), np.zeros(3))
    rel = b.relative_to(a)
    got = out.relative_to(Pose2D(3.0, 3.0, -1.0))
    assert (got.x, got.y, got.theta) == pytest.approx((rel.x, rel.y, rel.theta), abs=1e-12)


def test_the_world_and_the_filter_share_one_motion_model():
    import gridmap.motion
    import localization.motion

    import sim.odometry

    assert sim.odometry.odometry_delta is localization.motion.odometry_delta \
        is gridmap.motion.odometry_delta
    rng = np.random.default_rng(3)
    alphas = (0.05, 0.01, 0.05, 0.01)
    for rot1, trans, rot2 in zip(rng.uniform(-4, 4, 200), rng.uniform(0, 1, 200),
                                 rng.uniform(-4, 4, 200)):
        world = sim.odometry.motion_sigmas((rot1, trans, rot2), alphas)
        filt = localization.motion.motion_sigmas((rot1, trans, rot2), alphas)
        np.testing.assert_allclose(world, filt, rtol=1e-14)   # equal but for the last bit
