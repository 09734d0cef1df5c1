"""The simulated lidar: exact ranges against geometry, range noise, range limits, and the beam
casting kernel against slow references (brute-force NumPy and pymunk's own segment query)."""

import math
from pathlib import Path

import numpy as np
import pytest

import sim
from gridmap import Pose2D
from sim import geometry as geo
from sim import lidar as lid

WAREHOUSE = Path(__file__).resolve().parents[1] / "scenarios" / "aws_small_warehouse.yaml"


def room(objects=(), lidar=None, bounds=(0.0, 0.0, 4.0, 3.0), people=(), route=((2.0, 1.5),),
         start=(1.0, 1.0, 0.0)):
    ld = {"mount": [0.2, 0.1, 0.3], "fov_deg": 270, "beams": 1081, "range_max": 20.0,
          "range_noise_std": 0.0, "rate_hz": 10}
    ld.update(lidar or {})
    return sim.scenario_from_dict({
        "name": "room", "seed": 3,
        "world": {"bounds": list(bounds), "wall_thickness": 0.1, "movable": list(objects)},
        "robot": {"start": list(start), "lidars": [ld]},
        "sessions": [{"name": "S1", "route": [list(p) for p in route], "people": list(people)}]})


def analytic_room_ranges(sensor: Pose2D, angles, bounds):
    """Distance from the sensor to the walls of an empty rectangular room, beam by beam."""
    x0, y0, x1, y1 = bounds
    a = sensor.theta + np.asarray(angles)
    c, s = np.cos(a), np.sin(a)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (x1 - sensor.x) / c, np.where(c < 0, (x0 - sensor.x) / c, np.inf))
        ty = np.where(s > 0, (y1 - sensor.y) / s, np.where(s < 0, (y0 - sensor.y) / s, np.inf))
    return np.minimum(tx, ty)


def brute_force_ranges(sensor, angles, segments, circles, range_max):
    """Every beam against every segment (both faces) and circle: no culling at all."""
    a = sensor[2] + np.asarray(angles)
    d = np.stack([np.cos(a), np.sin(a)], axis=1)[:, None, :]
    p, e = segments[None, :, :2], segments[None, :, 2:] - segments[None, :, :2]
    w = p - sensor[None, None, :2]
    den = d[..., 0] * e[..., 1] - d[..., 1] * e[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[..., 0] * e[..., 1] - w[..., 1] * e[..., 0]) / den
        u = (w[..., 0] * d[..., 1] - w[..., 1] * d[..., 0]) / den
    t = np.where((den != 0) & (t > 0) & (u >= 0) & (u <= 1), t, np.inf).min(axis=1)
    for cx, cy, r in circles:
        m = np.array([cx - sensor[0], cy - sensor[1]])
        b = d[:, 0, :] @ m
        disc = b * b - (m @ m - r * r)
        hit = np.where((disc >= 0) & (b > 0), b - np.sqrt(np.maximum(disc, 0)), np.inf)
        t = np.minimum(t, hit)
    return np.where(t <= range_max, t, np.inf)


def test_empty_room_gives_the_analytic_ranges_without_noise():
    scn = room()
    world = sim.World(scn, 0)
    spec = scn.robot.lidars[0]
    for robot in (Pose2D(1.0, 1.0, 0.0), Pose2D(2.7, 0.6, 2.2), Pose2D(0.5, 2.4, -1.0)):
        scan = world.scan_without_people(robot)
        sensor = robot.compose(spec.mount)
        expected = analytic_room_ranges(sensor, scan.angles(), (0.0, 0.0, 4.0, 3.0))
        assert scan.ranges.dtype == np.float32 and scan.beams == 1081
        np.testing.assert_allclose(scan.ranges, expected, rtol=0, atol=1e-6)
        assert scan.angle_min == pytest.approx(-math.radians(135))
        assert scan.angle_increment == pytest.approx(math.radians(0.25))


def test_first_scan_of_a_run_matches_the_analytic_ranges():
    scn = room()
    msg = next(m for m in sim.World(scn, 0).run() if isinstance(m, sim.ScanMsg))
    assert msg.time == 0.0 and msg.true_pose == scn.robot.start
    sensor = scn.robot.start.compose(scn.robot.lidars[0].mount)
    expected = analytic_room_ranges(sensor, msg.scan.angles(), (0.0, 0.0, 4.0, 3.0))
    np.testing.assert_allclose(msg.scan.ranges, expected, rtol=0, atol=1e-6)


def test_a_circle_is_hit_at_its_near_side():
    scn = room([{"id": "drum", "center": [3.0, 1.5], "radius": 0.3}],
               lidar={"mount": [0.0, 0.0, 0.0]})
    world = sim.World(scn, 0)
    scan = world.scan_without_people(Pose2D(1.0, 1.5, 0.0))
    mid = int(np.argmin(np.abs(scan.angles())))
    assert scan.ranges[mid] == pytest.approx(1.7, abs=1e-6)


def test_beyond_range_max_is_inf():
    scn = room(bounds=(0.0, 0.0, 30.0, 3.0), lidar={"range_max": 5.0, "mount": [0, 0, 0]},
               start=(1.0, 1.5, 0.0), route=((2.0, 1.5),))
    scan = sim.World(scn, 0).scan_without_people(Pose2D(1.0, 1.5, 0.0))
    mid = int(np.argmin(np.abs(scan.angles())))
    assert np.isinf(scan.ranges[mid])                   # the far wall is 29 m away
    assert np.isfinite(scan.ranges).sum() > 900         # the side walls are near
    assert np.nanmax(scan.ranges[np.isfinite(scan.ranges)]) <= 5.0


def test_range_noise_has_the_configured_standard_deviation():
    scn = room(lidar={"range_noise_std": 0.02})
    world = sim.World(scn, 0, seed=11)
    poses = np.array([[1.0 + 0.05 * k, 1.0, 0.1 * k] for k in range(20)])
    exact = world.scans_without_people(poses, noise=False).astype(np.float64)
    noisy = world.scans_without_people(poses, noise=True).astype(np.float64)
    err = (noisy - exact).ravel()
    assert err.size == 20 * 1081
    assert abs(err.mean()) < 0.001
    assert err.std() == pytest.approx(0.02, rel=0.03)


def test_noise_in_the_run_has_the_configured_standard_deviation():
    scn = room(lidar={"range_noise_std": 0.01}, route=((3.0, 1.0),))
    world = sim.World(scn, 0, seed=5)
    errs = []
    for msg in world.run():
        if isinstance(msg, sim.ScanMsg):
            exact = world.scan_without_people(msg.true_pose).ranges.astype(np.float64)
            errs.append(msg.scan.ranges - exact)
    err = np.concatenate(errs)
    assert err.size > 10 * 1081
    assert err.std() == pytest.approx(0.01, rel=0.05)


@pytest.mark.parametrize("fov, beams", [(270, 1081), (360, 720), (90, 7)])
def test_kernel_matches_the_brute_force_reference(fov, beams):
    scn = sim.load_scenario(WAREHOUSE)
    world = sim.World(scn, "W3")
    spec = sim.LidarSpec(fov_deg=fov, beams=beams, range_max=12.0)
    rng = np.random.default_rng(0)
    people = np.array([[0.5, -3.0, 0.25], [-3.5, 4.0, 0.3]])
    circles = np.concatenate([world.circles, people])
    angles = spec.angle_min + spec.angle_increment * np.arange(beams)
    n = 0
    while n < 40:
        p = np.array([rng.uniform(-6.5, 6.5), rng.uniform(-10, 10), rng.uniform(-4, 4)])
        if (geo.point_box_distance(p[None, :2], world.boxes) < 0.05).any():
            continue
        if (geo.point_circle_distance(p[None, :2], people) < 0.05).any():
            continue
        n += 1
        got = lid.cast_ranges(p[None], spec, world.segments, circles)[0]
        ref = brute_force_ranges(p, angles, world.segments, circles, spec.range_max)
        np.testing.assert_array_equal(np.isinf(got), np.isinf(ref))
        fin = np.isfinite(ref)
        np.testing.assert_allclose(got[fin], ref[fin], rtol=0, atol=1e-9)


def test_kernel_matches_pymunk_segment_queries():
    import pymunk

    scn = sim.load_scenario(WAREHOUSE)
    world = sim.World(scn, "W2")
    space = pymunk.Space()
    for corners in geo.box_corners(world.boxes):
        space.add(pymunk.Poly(space.static_body, [tuple(map(float, c)) for c in corners]))
    spec = scn.robot.lidars[0]
    rng = np.random.default_rng(1)
    checked = 0
    for _ in range(30):
        p = np.array([rng.uniform(-6.5, 6.5), rng.uniform(-10, 10), rng.uniform(-4, 4)])
        if space.point_query_nearest(tuple(p[:2]), 0.05, pymunk.ShapeFilter()) is not None:
            continue
        got = lid.cast_ranges(p[None], spec, world.segments, world.circles)[0]
        for i in range(0, spec.beams, 20):
            a = p[2] + spec.angle_min + i * spec.angle_increment
            end = (p[0] + 20 * math.cos(a), p[1] + 20 * math.sin(a))
            hit = space.segment_query_first(tuple(p[:2]), end, 0.0, pymunk.ShapeFilter())
            ref = math.inf if hit is None else hit.alpha * 20.0
            assert got[i] == pytest.approx(ref, abs=1e-6)
            checked += 1
    assert checked > 500


def test_scan_of_a_built_in_warehouse_pose_sees_its_walls_and_racks():
    scn = sim.load_scenario(WAREHOUSE)
    scan = sim.World(scn, 0).scan_without_people(scn.robot.start)
    assert np.isfinite(scan.ranges).all()              # a closed building: every beam returns
    assert scan.ranges.min() > 0.3 and scan.ranges.max() < 22.0
