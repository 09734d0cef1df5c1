"""The world's run: message order and rates, reproducibility, people who keep out of objects and
whom the lidar sees, a robot that drives its route and waits for people, odometry noise applied
per message."""

import math

import numpy as np
import pytest

import sim
from gridmap import Pose2D, Scan
from sim import geometry as geo
from sim import lidar as lid
from sim.odometry import motion_sigmas, odometry_delta


def scenario(people=(), route=((5.0, 1.0), (5.0, 4.0), (1.0, 4.0), (1.0, 1.0)), noise=0.01,
             physics_hz=20.0, alphas=(0.05, 0.01, 0.05, 0.01), bounds=(0.0, 0.0, 6.0, 5.0),
             movable=None):
    movable = movable if movable is not None else [
        {"id": "pallet", "center": [3.0, 2.5], "size": [1.2, 0.8]},
        {"id": "drum", "center": [4.0, 2.4], "radius": 0.3}]
    return sim.scenario_from_dict({
        "name": "room", "seed": 9, "physics_hz": physics_hz,
        "world": {"bounds": list(bounds), "wall_thickness": 0.1, "movable": movable},
        "robot": {"start": [1.0, 1.0, 0.0], "radius": 0.3, "odometry_noise": list(alphas),
                  "lidars": [{"mount": [0.2, 0.0, 0.0], "fov_deg": 270, "beams": 541,
                              "range_max": 10.0, "range_noise_std": noise, "rate_hz": 10},
                             {"mount": [-0.2, 0.0, math.pi], "fov_deg": 180, "beams": 181,
                              "range_max": 10.0, "range_noise_std": noise, "rate_hz": 5}]},
        "sessions": [{"name": "S1", "route": [list(p) for p in route], "people": list(people)}]})


CROWD = [{"route": [[0.5, 4.5], [5.5, 4.5], [5.5, 0.5], [0.5, 0.5]], "speed": 1.2},
         {"wander": [0.3, 0.3, 5.7, 4.7], "count": 3, "speed": 1.0}]


def record(world):
    out = []
    for m in world.run():
        if isinstance(m, sim.ScanMsg):
            out.append(("scan", m.time, m.lidar, m.scan.ranges.tobytes(), m.true_pose,
                        m.odom_pose, world.people().tobytes()))
        else:
            out.append(("odom", m.time, m.pose, m.true_pose))
    return out


def test_two_runs_with_one_seed_are_identical_and_other_seeds_differ():
    scn = scenario(CROWD)
    a = record(sim.World(scn, 0, seed=4))
    b = record(sim.World(scn, 0, seed=4))
    assert len(a) > 200 and a == b
    ss = np.random.SeedSequence(123)
    assert record(sim.World(scn, "S1", seed=ss)) == record(sim.World(scn, "S1", seed=ss))
    c = record(sim.World(scn, 0, seed=5))
    assert a[:50] != c[:50]


def test_messages_come_in_time_order_at_their_rates():
    scn = scenario(CROWD)
    world = sim.World(scn, 0)
    msgs = list(world.run())
    times = [m.time for m in msgs]
    assert times == sorted(times) and times[0] == 0.0
    odom = [m for m in msgs if isinstance(m, sim.OdometryMsg)]
    scans = [[m for m in msgs if isinstance(m, sim.ScanMsg) and m.lidar == k] for k in (0, 1)]
    np.testing.assert_allclose([m.time for m in odom], np.arange(len(odom)) / 20.0, atol=1e-12)
    np.testing.assert_allclose([m.time for m in scans[0]], np.arange(len(scans[0])) / 10.0,
                               atol=1e-12)
    np.testing.assert_allclose([m.time for m in scans[1]], np.arange(len(scans[1])) / 5.0,
                               atol=1e-12)
    assert scans[1][0].scan.beams == 181 and scans[0][0].scan.beams == 541
    # odometry first at a shared time; its pose is the scan's odometry pose
    for k, m in enumerate(msgs):
        if isinstance(m, sim.ScanMsg) and abs(m.time * 20 - round(m.time * 20)) < 1e-9:
            prev = max(j for j in range(k) if isinstance(msgs[j], sim.OdometryMsg))
            assert msgs[prev].time == m.time and msgs[prev].pose == m.odom_pose
            assert msgs[prev].true_pose == m.true_pose and m.scan.time == m.time
    # the odom frame starts at the start pose
    assert odom[0].pose == odom[0].true_pose == scn.robot.start
    assert world.finished and math.dist((world.true_pose.x, world.true_pose.y), (1.0, 1.0)) < 0.06
    assert world.time == times[-1]


def test_robot_drives_along_its_route():
    scn = scenario(noise=0.0)
    world = sim.World(scn, 0)
    pts = np.array([[1.0, 1.0], [5.0, 1.0], [5.0, 4.0], [1.0, 4.0], [1.0, 1.0]])
    worst, top = 0.0, 0.0
    last = None
    for m in world.run():
        if isinstance(m, sim.OdometryMsg):
            p = np.array([m.true_pose.x, m.true_pose.y])
            d = min(np.hypot(*(p - (a + np.clip((p - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
                                    * (b - a)))) for a, b in zip(pts[:-1], pts[1:]))
            worst = max(worst, d)
            if last is not None:
                top = max(top, np.hypot(*(p - last)) * 20)
            last = p
    assert world.finished and worst < 0.05
    assert top <= scn.robot.max_speed + 1e-6
    assert 20 < world.time < 60                    # 14 m at up to 0.6 m/s, plus turns


def test_the_lidar_sees_people_exactly():
    scn = scenario(CROWD, noise=0.0)
    world = sim.World(scn, 0, seed=2)
    seen = 0
    for m in world.run():
        if isinstance(m, sim.ScanMsg):
            spec = scn.robot.lidars[m.lidar]
            circles = np.concatenate([world.circles, world.people()])
            sensor = lid.sensor_poses(m.true_pose.as_array()[None], spec.mount)
            exact = lid.cast_ranges(sensor, spec, world.segments, circles)[0]
            np.testing.assert_array_equal(m.scan.ranges, exact.astype(np.float32))
            empty = world.scan_without_people(m.true_pose, m.lidar).ranges
            seen += int((m.scan.ranges < empty - 0.05).any())
    assert seen > 50                                  # people do show up in the scans


def test_people_never_overlap_walls_or_objects_over_a_long_run():
    movable = [{"id": f"box{k}", "center": c, "size": [0.8, 0.6], "yaw": y}
               for k, (c, y) in enumerate([([2.0, 2.0], 0.3), ([4.0, 3.0], -0.5),
                                           ([2.0, 3.4], 1.0), ([4.3, 1.9], 0.0)])]
    movable.append({"id": "drum", "center": [3.1, 2.8], "radius": 0.25})
    route = [[5.4, 0.5], [5.4, 4.5], [0.6, 4.5], [0.6, 0.5]] * 3
    people = [{"wander": [0.3, 0.3, 5.7, 4.7], "count": 8, "speed": 1.3},
              {"route": [[0.4, 0.4], [5.6, 0.4], [5.6, 4.6], [0.4, 4.6]], "speed": 1.4}]
    scn = scenario(people, route=[tuple(p) for p in route] + [(0.6, 0.6)], movable=movable)
    world = sim.World(scn, 0, seed=8)
    worst_obj, worst_robot, n = np.inf, np.inf, 0
    for m in world.run():
        if not isinstance(m, sim.OdometryMsg):
            continue
        P = world.people()
        d_obj = np.minimum(geo.point_box_distance(P[:, :2], world.boxes).min(axis=1),
                           geo.point_circle_distance(P[:, :2], world.circles).min(axis=1))
        worst_obj = min(worst_obj, (d_obj - P[:, 2]).min())
        d_rob = np.hypot(P[:, 0] - m.true_pose.x, P[:, 1] - m.true_pose.y) - P[:, 2] - 0.3
        worst_robot = min(worst_robot, d_rob.min())
        n += 1
    assert world.finished and n * 0.05 > 100          # a long run: over 100 s of walking
    assert worst_obj >= -1e-9                          # never inside a wall or an object
    assert worst_robot >= -1e-9                        # nobody is ever inside the robot


def test_robot_waits_for_a_person_in_its_way():
    people = [{"route": [[5.0, 1.0], [1.5, 1.0]], "loop": False, "speed": 0.8}]
    scn = scenario(people, route=((5.0, 1.0),), movable=[])
    world = sim.World(scn, 0, seed=1)
    gap, slowed = np.inf, False
    prev = None
    for m in world.run():
        if isinstance(m, sim.OdometryMsg):
            p = world.people()[0]
            gap = min(gap, math.hypot(p[0] - m.true_pose.x, p[1] - m.true_pose.y) - p[2] - 0.3)
            if prev is not None and m.true_pose.x - prev < 0.01 and 0.5 < m.true_pose.x < 4.5:
                slowed = True
            prev = m.true_pose.x
    assert world.finished and slowed and gap > 0.0


def test_scan_without_people_matches_a_run_without_people():
    scn = scenario(noise=0.0)
    world = sim.World(scn, 0)
    for m in world.run():
        if isinstance(m, sim.ScanMsg) and m.lidar == 0 and m.time > 3:
            again = world.scan_without_people(m.true_pose)
            np.testing.assert_array_equal(again.ranges, m.scan.ranges)
            batch = world.scans_without_people(np.array([m.true_pose.as_array()] * 3))
            assert batch.shape == (3, 541) and (batch == m.scan.ranges).all()
            break


def test_odometry_noise_is_applied_per_message_not_per_physics_step():
    # four physics steps per odometry message: noise per step would shrink the variance 4x
    scn = scenario(physics_hz=80.0, alphas=(0.2, 0.05, 0.2, 0.05),
                   route=((5.0, 1.0), (5.0, 4.0), (1.0, 4.0), (1.0, 1.0), (5.0, 1.0),
                          (5.0, 4.0), (1.0, 4.0), (1.0, 1.0)))
    world = sim.World(scn, 0, seed=3)
    odom = [m for m in world.run() if isinstance(m, sim.OdometryMsg)]
    z = []
    for a, b in zip(odom[:-1], odom[1:]):
        true = odometry_delta(a.true_pose, b.true_pose)
        if true[1] < 0.02 and abs(true[2]) < 1e-3:
            continue                                   # standing still: no noise at all
        meas = odometry_delta(a.pose, b.pose)
        if true[1] < 0.01:                             # turning on the spot: rot1 is 0
            meas = (0.0, meas[1], (b.pose.theta - a.pose.theta + math.pi) % (2 * math.pi)
                    - math.pi)
        sig = motion_sigmas(true, scn.robot.odometry_noise)
        err = np.array(meas) - np.array(true)
        err[[0, 2]] = (err[[0, 2]] + math.pi) % (2 * math.pi) - math.pi
        keep = sig > 1e-9
        z.extend((err[keep] / sig[keep]).tolist())
    z = np.array(z)
    assert z.size > 1000
    assert np.var(z) == pytest.approx(1.0, abs=0.15)
    final = odom[-1]
    drift = math.hypot(final.pose.x - final.true_pose.x, final.pose.y - final.true_pose.y)
    assert drift > 0.01                                # it does drift


def test_world_state_and_truth_helpers():
    scn = scenario(CROWD)
    world = sim.World(scn, "S1")
    assert world.true_pose == world.odom_pose == scn.robot.start and world.time == 0.0
    assert world.people().shape == (4, 3)
    g = world.ground_truth()
    assert g.same_frame(sim.grid_frame(scn))
    gen = world.run()
    next(gen)
    with pytest.raises(RuntimeError):
        next(world.run())
    with pytest.raises(sim.ScenarioError, match="no session named 'S2'"):
        sim.World(scn, "S2")
    back = world.scan_without_people(Pose2D(2.0, 1.0, 0.0), lidar=1)
    assert isinstance(back, Scan) and back.beams == 181
