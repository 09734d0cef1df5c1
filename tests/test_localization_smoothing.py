"""The smoothing of a recorded localisation with the odometry (localization.smoothing): a
jittering localisation is smoothed, amcl's (corrections now and then) is left as recorded, a
relocalisation restarts the window, and bad settings are refused."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gridmap import Pose2D
from localization import LocalizationError
from localization.smoothing import SMOOTH_WINDOW, PoseSmoother

RATE = 10.0          # [Hz]


def drive(seconds=20.0, speed=0.5, turn=0.1):
    """True poses along an arc at 10 Hz, and a drifting odometry frame (odom = D (+) true,
    D turning slowly), as wheel odometry is smooth but not in the map frame."""
    out = []
    for k in range(int(seconds * RATE)):
        t = k / RATE
        yaw = turn * t
        true = Pose2D(speed / turn * math.sin(yaw), speed / turn * (1 - math.cos(yaw)), yaw)
        drift = Pose2D(1.0 + 0.002 * t, -2.0, 0.3 + 0.0005 * t)
        out.append((t, true, drift.compose(true)))
    return out


def errors(poses, truth):
    pos = [math.hypot(p.x - q.x, p.y - q.y) for p, q in zip(poses, truth)]
    yaw = [abs(math.degrees(p.theta - q.theta)) for p, q in zip(poses, truth)]
    return float(np.median(pos)), float(np.median(yaw))


def test_a_jittering_localisation_is_smoothed_to_a_fraction_of_its_jitter():
    rng = np.random.default_rng(3)
    smoother = PoseSmoother()
    given, used, truth = [], [], []
    for t, true, odom in drive():
        recorded = Pose2D(true.x + rng.normal(0, 0.02), true.y + rng.normal(0, 0.02),
                          true.theta + rng.normal(0, math.radians(0.5)))
        given.append(recorded)
        used.append(smoother(t, recorded, odom))
        truth.append(true)
    raw, smooth = errors(given[30:], truth[30:]), errors(used[30:], truth[30:])
    assert raw[0] > 0.02 and smooth[0] < 0.35 * raw[0], (raw, smooth)
    assert smooth[1] < 0.35 * raw[1], (raw, smooth)
    assert smoother.smoothed > 0.9 * len(used) and smoother.restarts == 0


def test_amcl_s_corrections_now_and_then_are_used_as_recorded():
    """amcl moves map -> odom only at its filter updates (here every 0.5 s, by 1-3 cm):
    between them the recorded pose follows the odometry exactly; each update corrects."""
    rng = np.random.default_rng(4)
    smoother = PoseSmoother()
    for k, (t, true, odom) in enumerate(drive()):
        if k % 5 == 0:          # a filter update: its estimate, off by its own error
            estimate = true.compose(Pose2D(rng.normal(0, 0.02), rng.normal(0, 0.02),
                                           rng.normal(0, 0.005)))
            map_odom = estimate.compose(odom.inverse())
        recorded = map_odom.compose(odom)
        assert smoother(t, recorded, odom) == recorded
    assert smoother.smoothed == 0


def test_a_relocalisation_restarts_the_window_and_is_used_at_once():
    rng = np.random.default_rng(5)
    smoother = PoseSmoother()
    for t, true, odom in drive(seconds=10.0):
        shift = 0.6 if t >= 5.0 else 0.0            # the localisation jumps by 0.6 m at 5 s
        recorded = Pose2D(true.x + shift + rng.normal(0, 0.02), true.y + rng.normal(0, 0.02),
                          true.theta + rng.normal(0, 0.008))
        used = smoother(t, recorded, odom)
        if t >= 5.0:
            assert abs(used.x - (true.x + shift)) < 0.05, t   # no blend with the old poses
    assert smoother.restarts == 1


def test_a_pose_that_is_not_finite_passes_and_leaves_the_window_alone():
    rng = np.random.default_rng(6)
    smoother, used = PoseSmoother(), []
    for k, (t, true, odom) in enumerate(drive(seconds=6.0)):
        recorded = Pose2D(true.x + rng.normal(0, 0.02), true.y + rng.normal(0, 0.02),
                          true.theta + rng.normal(0, 0.008))
        if k == 30:
            recorded = Pose2D(math.nan, true.y, true.theta)
        out = smoother(t, recorded, odom)
        used.append(out)
        if k == 30:
            assert out is recorded
    assert all(p.is_finite() for k, p in enumerate(used) if k != 30)
    assert smoother.smoothed > 40


def test_time_going_back_starts_the_window_afresh():
    """A new pass over a log, or a new session, starts at an earlier time: the poses of the
    last one are no longer in the window."""
    smoother = PoseSmoother()
    rng = np.random.default_rng(7)
    for t, true, odom in drive(seconds=5.0):
        smoother(t, Pose2D(true.x + rng.normal(0, 0.02), true.y, true.theta), odom)
    far = Pose2D(50.0, 50.0, 1.0)
    assert smoother(0.0, far, Pose2D(0.0, 0.0, 0.0)) == far        # nothing to smooth with
    assert smoother.restarts == 0


def test_without_a_pose_or_with_no_window_the_recorded_pose_is_used():
    odom = Pose2D(0.0, 0.0, 0.0)
    assert PoseSmoother(0.0)(1.0, Pose2D(1.0, 2.0, 0.1), odom) == Pose2D(1.0, 2.0, 0.1)
    assert PoseSmoother()(1.0, None, odom) is None
    assert PoseSmoother()(1.0, Pose2D(1.0, 2.0, 0.1), None) == Pose2D(1.0, 2.0, 0.1)
    assert SMOOTH_WINDOW == 2.0


@pytest.mark.parametrize("kwargs, word", [({"window": -1.0}, "window"),
                                          ({"window": 61.0}, "window"),
                                          ({"window": True}, "window"),
                                          ({"jump": float("nan")}, "jump"),
                                          ({"jump_deg": "5"}, "jump_deg")])
def test_bad_settings_are_refused_by_name(kwargs, word):
    with pytest.raises(LocalizationError, match=f"pose smoothing: {word} must be a number"):
        PoseSmoother(**kwargs)
