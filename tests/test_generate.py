"""Generated warehouses (scenarios/generator.py: `scenarios.generate`, `mapupdate generate`):
valid scenarios, the same file for the same seed, and rearrangements that the session's route
can observe."""

from __future__ import annotations

import math

import numpy as np
import pytest

import evaluation as ev
import sim
from gridmap import Pose2D
from mapupdate import main
from scenarios.generator import GenerateError, ROUTE_STEP, generate, scenario_yaml, write_generated
from sim import lidar as lid


def test_the_same_seed_writes_the_same_file_byte_for_byte(tmp_path, capsys):
    assert main(["generate", "--seed", "5", "--out", str(tmp_path / "a.yaml")]) == 0
    write_generated(5, tmp_path / "b.yaml")
    write_generated(6, tmp_path / "c.yaml")
    a = (tmp_path / "a.yaml").read_bytes()
    assert a == (tmp_path / "b.yaml").read_bytes() != (tmp_path / "c.yaml").read_bytes()
    scn = sim.load_scenario(tmp_path / "a.yaml")           # today's format, checks included
    assert scn.name == "generated_5_30x20" and len(scn.sessions) == 4
    assert scn.sessions[0].mapping and all(s.quick_route for s in scn.sessions[1:])


@pytest.mark.parametrize("size, fov", [((15, 10), 270), ((60, 40), 360)])
def test_the_smallest_and_largest_buildings(size, fov):
    scn = sim.scenario_from_dict(generate(2, size=size, sessions=2, fov=fov))
    x0, y0, x1, y1 = scn.world.bounds
    assert (x1 - x0, y1 - y0) == size and scn.robot.lidars[0].fov_deg == fov
    racks = [o for o in scn.world.static if o.kind == "rack"]
    pillars = [o for o in scn.world.static if o.kind == "pillar"]
    assert len(racks) >= 2 and len(pillars) >= 2
    assert {o.kind for o in scn.world.movable} <= {"pallet", "drum", "box"}


@pytest.mark.parametrize("kwargs, message", [
    ({"size": (14, 10)}, "outside 15 x 10 to 60 x 40"),
    ({"size": (30, 41)}, "outside"),
    ({"sessions": 1}, "from 2 .* to 100"),
    ({"sessions": 1_000_000_000}, "from 2 .* to 100, got 1000000000"),
    ({"fov": 180}, "270 or 360")])
def test_bad_arguments_are_refused_with_one_line(kwargs, message):
    with pytest.raises(GenerateError, match=message):
        generate(1, **kwargs)


def test_bad_arguments_on_the_command_line_give_one_line(tmp_path, capsys):
    assert main(["generate", "--seed", "1", "--out", str(tmp_path / "x.yaml"),
                 "--fov", "180"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["mapupdate generate: error: fov must be 270 or 360, got 180"]
    assert not (tmp_path / "x.yaml").exists()


def _route_poses(scn, route) -> np.ndarray:
    pts = np.vstack([[scn.robot.start.x, scn.robot.start.y], np.asarray(route, float)])
    out = []
    for a, b in zip(pts[:-1], pts[1:]):
        length = float(np.hypot(*(b - a)))
        for s in np.arange(0.0, length, ROUTE_STEP):
            p = a + (b - a) * s / max(length, 1e-9)
            out.append((p[0], p[1], math.atan2(b[1] - a[1], b[0] - a[0])))
    return np.array(out)


def _observable(scn, world, route) -> np.ndarray:
    """Cells that noise-free beams from poses along ``route`` (about the gate's spacing) hit
    or pass through within 10 m in at least 7 scans: the evaluation's rule."""
    spec = scn.robot.lidars[0]
    poses = _route_poses(scn, route)
    counter = ev.ObservationCounter(sim.grid_frame(scn))
    ranges = world.scans_without_people(poses, 0)
    angles = spec.angle_min + spec.angle_increment * np.arange(spec.beams)
    for sensor, r in zip(lid.sensor_poses(poses, spec.mount), ranges):
        counter.add_scan(Pose2D(*map(float, sensor)), r, angles)
    return counter.observable()


def _object_cells(frame, o) -> np.ndarray:
    """Cells within two cells of the object's bounding circle."""
    rows, cols = np.indices(frame.shape)
    x, y = frame.cell_to_world(rows, cols)
    reach = (o.radius if o.is_circle else math.hypot(*o.size) / 2) + 2 * frame.resolution
    return np.hypot(x - o.center[0], y - o.center[1]) <= reach


def _changes_leave_targets(scn, i: int) -> None:
    before, after = sim.World(scn, i - 1, 0), sim.World(scn, i, 0)
    wrong_occ, wrong_free = ev.wrong_cells(before.ground_truth(), after.ground_truth())
    frame = sim.grid_frame(scn)
    was = {o.id: o for o in scn.obstacles(i - 1)}
    now = {o.id: o for o in scn.obstacles(i)}
    for route in (scn.sessions[i].route, scn.sessions[i].quick_route):
        targets = (wrong_occ | wrong_free) & _observable(scn, after, route)
        for ch in scn.sessions[i].changes:
            # where the object was (move, remove) and where it is (move, add)
            places = [o for o in (was.get(ch.id), now.get(ch.id)) if o is not None]
            assert places
            for o in places:
                n = int((targets & _object_cells(frame, o)).sum())
                assert n > 0, f"{scn.name} {scn.sessions[i].name}: {ch.kind} {ch.id} at " \
                              f"{o.center} leaves no observable target"


def _check_seeds(seeds) -> None:
    sizes = [(15, 10), (22, 14)]
    for seed in seeds:
        scn = sim.scenario_from_dict(generate(seed, size=sizes[seed % 2], sessions=3,
                                              fov=(270, 360)[seed % 3 == 0]), f"seed {seed}")
        for i in range(1, len(scn.sessions)):
            assert 2 <= len(scn.sessions[i].changes) <= 6 and scn.sessions[i].people
            _changes_leave_targets(scn, i)


def test_ten_seeds_validate_and_every_change_leaves_observable_targets_on_its_route():
    _check_seeds(range(10))


@pytest.mark.slow
def test_forty_seeds_more_validate_and_leave_observable_targets():
    """With the fast test's ten: fifty generated seeds."""
    _check_seeds(range(10, 50))


def test_the_package_offers_generate():
    import scenarios

    assert scenarios.generate(9, size=(15, 10), sessions=2) == generate(9, size=(15, 10),
                                                                        sessions=2)


def test_the_text_is_the_tree():
    import yaml

    tree = generate(9, size=(15, 10), sessions=2)
    assert yaml.safe_load(scenario_yaml(tree, "header")) == tree
