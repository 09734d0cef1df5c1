"""Driving the world by command, step by step: the route follower's own commands through
``World.step`` replay ``World.run`` exactly; moves into walls and objects are refused and
counted; commands are clipped to the robot's limits."""

import numpy as np
import pytest

import sim
from test_sim_world import CROWD, record, scenario


def drive_route(world):
    """``record(world)`` of ``World.run``, reproduced with ``route_command`` and ``drive``."""
    out = []
    limit = world.time_limit
    while True:
        v, w = world.route_command()
        for m in world.drive(v, w):
            if isinstance(m, sim.ScanMsg):
                out.append(("scan", m.time, m.lidar, m.scan.ranges.tobytes(), m.true_pose,
                            m.odom_pose, world.people().tobytes()))
            else:
                out.append(("odom", m.time, m.pose, m.true_pose))
        f = world.follower
        if (f.done and f.v == 0.0 and f.w == 0.0) or world.time >= limit:
            return out


def test_route_commands_through_step_replay_run_bit_for_bit():
    scn = scenario(CROWD)
    a = record(sim.World(scn, 0, seed=4))
    world = sim.World(scn, 0, seed=4)
    b = drive_route(world)
    assert len(a) > 200 and a == b
    assert world.collisions == 0


def test_a_move_into_a_wall_is_refused_and_counted():
    world = sim.World(scenario(), 0, seed=1)      # starts at (1, 1) facing +x, radius 0.3
    # backwards into the west wall (x = 0): 0.7 m of room, 0.6 m/s for 3 s
    msgs = world.step(-0.6, 0.0, n_steps=60)
    assert world.collisions > 0
    assert 0.3 - 1e-6 <= world.true_pose.x < 0.3 + 0.6 * world.physics_dt
    assert msgs[-1].time == pytest.approx(3.0)
    # turning on the spot against the wall is never refused
    n = world.collisions
    world.step(0.0, 1.0, n_steps=10)
    assert world.collisions == n and world.true_pose.theta == pytest.approx(0.5)


def test_commands_are_clipped_to_the_robot_limits_and_step_does_not_mix_with_run():
    scn = scenario()
    world = sim.World(scn, 0, seed=1)
    world.step(10.0, 0.0, n_steps=20)                 # 1 s at most max_speed
    assert world.true_pose.x == pytest.approx(1.0 + scn.robot.max_speed, abs=1e-9)
    world.step(0.0, -50.0, n_steps=10)                # 0.5 s at most max_turn_rate
    assert world.true_pose.theta == pytest.approx(-0.5 * scn.robot.max_turn_rate, abs=1e-9)
    with pytest.raises(RuntimeError):
        next(world.run())
    other = sim.World(scn, 0, seed=1)
    next(other.run())
    with pytest.raises(RuntimeError):
        other.step(0.1, 0.0)
    with pytest.raises(ValueError):
        sim.World(scn, 0, seed=1).step(float("nan"), 0.0)
    assert not sim.World(scn, 0, seed=1).step(0.1, 0.0, n_steps=0)


def test_step_messages_arrive_at_their_rates():
    world = sim.World(scenario(), 0, seed=2)
    msgs = world.step(0.2, 0.1, n_steps=20)
    odo = [m for m in msgs if isinstance(m, sim.OdometryMsg)]
    scans = [m for m in msgs if isinstance(m, sim.ScanMsg)]
    assert len(odo) == 21 and len(scans) == 11 + 6    # t = 0 .. 1 s inclusive
    assert np.all(np.diff([m.time for m in msgs]) >= 0)


def test_looking_draws_nothing_and_the_clocks_agree():
    scn = scenario(CROWD)
    a, b = sim.World(scn, 0, seed=3), sim.World(scn, 0, seed=3)
    first = a.exact_scan(0)
    assert first.ranges.shape == (541,) and np.isfinite(first.ranges).any()
    for _ in range(5):
        a.exact_scan(1)
        assert [m.time for m in a.step(0.3, 0.2)] == [m.time for m in b.step(0.3, 0.2)]
    assert record_scans(a) == record_scans(b)
    assert a.elapsed == pytest.approx(9 * a.physics_dt)     # 5 steps, then 4 in record_scans
    assert a.robot_pose == b.robot_pose


def record_scans(world):
    return [m.scan.ranges.tobytes() for m in world.step(0.3, 0.0, n_steps=4)
            if isinstance(m, sim.ScanMsg)]
