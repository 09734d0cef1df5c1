"""Scenario files: the built-in warehouse, cumulative changes, and every invalid scenario
refused with a message that names the key or the object."""

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml

import sim
from sim import geometry as geo

WAREHOUSE = Path(__file__).resolve().parents[1] / "scenarios" / "aws_small_warehouse.yaml"

BASE = {
    "name": "room", "seed": 1, "resolution": 0.05,
    "world": {"bounds": [0.0, 0.0, 6.0, 4.0], "wall_thickness": 0.1,
              "static": [{"id": "post", "center": [5.0, 3.0], "radius": 0.2}],
              "movable": [{"id": "pallet_1", "center": [3.0, 2.0], "size": [1.2, 0.8]},
                          {"id": "drum", "center": [1.5, 3.2], "radius": 0.3}]},
    "robot": {"start": [0.6, 0.6, 0.0],
              "lidars": [{"mount": [0.2, 0.0, 0.0], "fov_deg": 270, "beams": 541,
                          "range_max": 10.0}]},
    "sessions": [
        {"name": "S1", "mapping": True, "route": [[5.2, 0.6], [5.2, 1.6]]},
        {"name": "S2", "route": [[5.2, 0.6]],
         "changes": [{"move": "pallet_1", "to": [3.0, 3.2, 0.0]}, {"remove": "drum"},
                     {"add": {"id": "box", "center": [1.5, 2.5], "size": [0.5, 0.5]}}],
         "people": [{"route": [[1.0, 1.5], [4.0, 1.5]], "speed": 1.0},
                    {"wander": [0.5, 0.5, 2.5, 1.5], "count": 2}]},
    ],
}


def load(data):
    return sim.scenario_from_dict(data, "test.yaml")


def refused(data, *fragments):
    with pytest.raises(sim.ScenarioError) as e:
        load(data)
    msg = str(e.value)
    for f in fragments:
        assert f in msg, msg
    return msg


def edit(fn):
    data = copy.deepcopy(BASE)
    fn(data)
    return data


def test_the_base_scenario_loads_with_defaults():
    scn = load(BASE)
    assert scn.robot.radius == 0.35 and scn.robot.max_speed == 0.6
    assert scn.robot.odometry_noise == (0.05, 0.01, 0.05, 0.01)
    ld = scn.robot.lidars[0]
    assert ld.mount == sim.scenario.Pose2D(0.2, 0.0, 0.0) and ld.rate_hz == 10
    assert ld.range_min == 0.05 and ld.range_noise_std == 0.01
    assert scn.sessions[0].mapping and not scn.sessions[1].mapping
    assert scn.session_index("S2") == 1 and scn.session_index(0) == 0


def test_changes_are_cumulative_and_in_order():
    scn = load(BASE)
    s1 = {o.id: o for o in scn.obstacles("S1")}
    s2 = {o.id: o for o in scn.obstacles("S2")}
    assert set(s1) == {"post", "pallet_1", "drum"}
    assert set(s2) == {"post", "pallet_1", "box"}
    assert s1["pallet_1"].center == (3.0, 2.0) and s2["pallet_1"].center == (3.0, 3.2)
    assert not s2["post"].movable and s2["box"].movable


def test_a_move_without_yaw_keeps_the_yaw():
    data = edit(lambda d: d["sessions"][1]["changes"].__setitem__(0, {"move": "pallet_1",
                                                                      "to": [3.0, 3.2]}))
    data["world"]["movable"][0]["yaw"] = 0.0
    scn = load(data)
    assert scn.sessions[1].changes[0].to == (3.0, 3.2, 0.0)


@pytest.mark.parametrize("where, bad, good", [
    (("world", "movable", 0), "sise", "size"),
    (("robot",), "max_sped", "max_speed"),
    (("robot", "lidars", 0), "beam", "beams"),
    (("sessions", 1), "peeple", "people"),
    ((), "sesions", "sessions"),
])
def test_unknown_key_is_refused_with_the_nearest_valid_name(where, bad, good):
    def put(d):
        node = d
        for k in where:
            node = node[k]
        node[bad] = node.pop(good) if good in node else 1
    msg = refused(edit(put), f"unknown key {bad!r}", f"did you mean {good!r}")
    assert msg.startswith("test.yaml: ")


@pytest.mark.parametrize("path, key", [
    (("robot",), "start"),
    (("robot", "lidars", 0), "range_max"),
    (("world",), "bounds"),
    (("sessions", 0), "route"),
    (("world", "movable", 0), "id"),
])
def test_missing_field_is_refused_naming_the_key(path, key):
    def drop(d):
        node = d
        for k in path:
            node = node[k]
        del node[key]
    dotted = ".".join(f"[{k}]" if isinstance(k, int) else k for k in path).replace(".[", "[")
    refused(edit(drop), f"{dotted}.{key}", "missing")


def test_object_outside_the_walls_is_refused_naming_it():
    data = edit(lambda d: d["world"]["movable"][0].update(center=[5.9, 2.0]))
    refused(data, "pallet_1", "outside the walls")
    moved = edit(lambda d: d["sessions"][1]["changes"][0].update(to=[3.0, 3.9, 0.0]))
    refused(moved, "pallet_1", "outside the walls", "S2")


def test_route_waypoint_inside_an_object_is_refused_naming_it():
    data = edit(lambda d: d["sessions"][0]["route"].append([3.0, 2.0]))
    refused(data, "sessions[0].route[2]", "inside object 'pallet_1'")
    # in a later session the moved pallet is where the waypoint is
    data = edit(lambda d: d["sessions"][1]["route"].append([3.1, 3.3]))
    refused(data, "sessions[1].route[1]", "'pallet_1'")


def test_route_leg_through_an_object_is_refused():
    data = edit(lambda d: d["sessions"][0].update(route=[[0.6, 2.0], [5.2, 2.0]]))
    refused(data, "sessions[0].route[1]", "run into object 'pallet_1'")


def test_overlapping_objects_are_refused_naming_both():
    data = edit(lambda d: d["world"]["movable"].append(
        {"id": "pallet_2", "center": [3.5, 2.3], "size": [1.2, 0.8], "yaw": 0.3}))
    refused(data, "pallet_2", "overlaps object 'pallet_1'")
    added = edit(lambda d: d["sessions"][1]["changes"].append(
        {"add": {"id": "crate", "center": [5.0, 2.85], "radius": 0.2}}))
    refused(added, "crate", "overlaps object 'post'", "S2")


def test_touching_objects_are_allowed():
    data = edit(lambda d: d["world"]["movable"].append(
        {"id": "pallet_2", "center": [3.0, 1.2], "size": [1.2, 0.8]}))   # beside pallet_1
    data["sessions"][0]["route"] = [[5.2, 0.3], [5.2, 1.6]]
    data["robot"]["start"] = [0.6, 0.3, 0.0]
    data["robot"]["radius"] = 0.2
    data["sessions"][1]["route"] = [[5.2, 0.3]]
    data["sessions"][1]["people"][0]["route"] = [[1.0, 2.0], [2.0, 2.0]]
    assert len(load(data).obstacles(0)) == 4


@pytest.mark.parametrize("change, fragments", [
    ({"move": "palet_1", "to": [1, 1, 0]}, ("palet_1", "did you mean 'pallet_1'")),
    ({"remove": "post"}, ("'post' is static",)),
    ({"add": {"id": "pallet_1", "center": [1.0, 2.0], "radius": 0.1}}, ("'pallet_1' already exists",)),
    ({"move": "pallet_1"}, ("changes[3].to", "missing")),
    ({"move": "pallet_1", "remove": "drum"}, ("exactly one of",)),
])
def test_bad_changes_are_refused(change, fragments):
    refused(edit(lambda d: d["sessions"][1]["changes"].append(change)), *fragments)


def test_bad_values_are_refused_naming_the_key():
    refused(edit(lambda d: d["robot"]["lidars"][0].update(beams=0)), "lidars[0].beams")
    refused(edit(lambda d: d["robot"]["lidars"][0].update(fov_deg=400)), "fov_deg")
    refused(edit(lambda d: d["robot"].update(start=[0.6, 0.6])), "robot.start", "3 numbers")
    refused(edit(lambda d: d["sessions"][1]["people"][0].update(speed="fast")), "speed")
    refused(edit(lambda d: d["robot"].update(start=[3.0, 2.0, 0.0])), "robot.start",
            "'pallet_1'")
    refused(edit(lambda d: d["sessions"][1]["people"].append({"wander": [0, 0, 9, 1]})),
            "people[2].wander", "outside")
    refused(edit(lambda d: d["sessions"][1]["people"][0].update(route=[[3.0, 3.2], [4, 1.5]])),
            "people[0].route", "'pallet_1'")


def test_unreadable_files_are_refused_with_their_path(tmp_path):
    with pytest.raises(sim.ScenarioError, match="nope.yaml: scenario file not found"):
        sim.load_scenario(tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: [unclosed\n")
    with pytest.raises(sim.ScenarioError, match="bad.yaml: not valid YAML"):
        sim.load_scenario(bad)
    good = tmp_path / "good.yaml"
    good.write_text(yaml.safe_dump(BASE))
    assert sim.load_scenario(good).name == "room"


def test_the_built_in_warehouse():
    scn = sim.load_scenario(WAREHOUSE)
    assert [s.name for s in scn.sessions] == ["W1", "W2", "W3", "W4"]
    assert scn.sessions[0].mapping and not scn.sessions[0].people
    people = [sum(p.count for p in s.people) for s in scn.sessions]
    assert people[0] == 0 and people[1] < people[2] < people[3]
    assert all(len(s.changes) >= 3 for s in scn.sessions[1:])
    ids = {o.id for o in scn.obstacles("W1")}
    assert {"rack_f_bar1", "shelf_e1", "shelf_d1_leg1", "bucket_1", "clutter_a1", "clutter_c6",
            "clutter_d", "trash_can", "pallet_jack", "pallet_1"} <= ids
    lid = scn.robot.lidars[0]
    assert (lid.fov_deg, lid.beams, lid.range_max, lid.rate_hz) == (270, 1081, 20.0, 10)
    routes = [scn.sessions[i].route for i in (1, 2, 3)]
    assert routes[0] == routes[1] == routes[2]
    start = np.array([[scn.robot.start.x, scn.robot.start.y]])
    for r, bounds in ((routes[0], (60, 110)), (scn.sessions[0].route, (100, 160))):
        pts = np.vstack([start, np.asarray(r)])
        length = np.hypot(*np.diff(pts, axis=0).T).sum()
        assert bounds[0] <= length <= bounds[1]
        assert np.allclose(pts[-1], start[0])          # a loop, back at the dock


def test_built_in_routes_keep_clear_of_every_object_in_every_session():
    scn = sim.load_scenario(WAREHOUSE)
    start = [scn.robot.start.x, scn.robot.start.y]
    for i, s in enumerate(scn.sessions):
        boxes, circles = geo.obstacle_arrays(scn.obstacles(i), scn.world.bounds,
                                             scn.world.wall_thickness)
        pts = [start] + list(s.route)
        for a, b in zip(pts[:-1], pts[1:]):
            assert geo.segment_box_distance(a, b, boxes).min() >= scn.robot.radius + 0.05


def test_quick_variant_cuts_update_routes_and_keeps_mapping_and_beams():
    scn = sim.load_scenario(WAREHOUSE)
    q = sim.quick_variant(scn)
    assert q.robot.lidars == scn.robot.lidars
    assert q.sessions[0].route == scn.sessions[0].route          # W1 maps the whole warehouse
    assert all(len(a.route) < len(b.route) for a, b in zip(q.sessions[1:], scn.sessions[1:]))
    thin = sim.quick_variant(scn, beam_step=4)
    assert thin.robot.lidars[0].beams == 271
    assert thin.robot.lidars[0].angle_increment == pytest.approx(
        4 * scn.robot.lidars[0].angle_increment)


def test_quick_route_is_validated_and_used_by_quick_runs():
    data = edit(lambda d: d["sessions"][1].update(quick_route=[[3.1, 3.3]]))
    refused(data, "sessions[1].quick_route[0]", "'pallet_1'")
    scn = load(edit(lambda d: d["sessions"][1].update(quick_route=[[5.2, 1.0], [5.2, 0.6]])))
    assert sim.quick_variant(scn).sessions[1].route == ((5.2, 1.0), (5.2, 0.6))
    # an explicit length cuts the full route instead
    assert sim.quick_variant(scn, max_route_length=1.0).sessions[1].route == ((5.2, 0.6),)
