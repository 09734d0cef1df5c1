"""A fleet of robots and one map: robots that see each other, the scan-time queue, the gate per
robot in front of the shared updater, the merge of per-robot maps, and a removed box that only
one robot of two can see, freed in the fleet's map."""

import json
import math

import numpy as np
import pytest

import sim
from gridmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid, Pose2D
from scenarios.fleet import (FleetOptions, FleetSession, fleet_members, format_table,
                             run_fleet)
from scenarios.fleet_store import (FleetBoard, RobotMask, ScanQueue, SharedGate, merge_maps,
                                   shared_updater)
from scenarios.session import session_seeds
from sim.fleet import FleetMember, FleetWorld
from updater import ScanStatus, UpdaterConfig

import tiny_room

LIDAR = {"mount": [0.2, 0.0, 0.0], "fov_deg": 270, "beams": 271, "range_max": 10.0,
         "range_noise_std": 0.01, "rate_hz": 10}
BOX = (9.5, 1.2)           # the box removed in W2, in the east room
CRATE = (3.0, 2.2)         # a crate the store-mode test adds in the west room


def near_point(grid, xy, half: int) -> np.ndarray:
    row, col = grid.world_to_cell(np.array([xy[0]]), np.array([xy[1]]))
    out = np.zeros(grid.shape, bool)
    out[int(row[0]) - half:int(row[0]) + half + 1, int(col[0]) - half:int(col[0]) + half + 1] = 1
    return out


def two_rooms(changes=({"remove": "box"},)):
    """Two rooms side by side (12 x 6 m) joined by a door at the north end of the wall between
    them. From the west room's south half the wall hides the east room's south half, where a
    box is removed in W2."""
    return sim.scenario_from_dict({
        "name": "two_rooms", "seed": 3, "resolution": 0.05,
        "world": {"bounds": [0.0, 0.0, 12.0, 6.0], "wall_thickness": 0.1,
                  "static": [{"id": "wall", "center": [6.0, 2.25], "size": [0.2, 4.5]}],
                  "movable": [{"id": "box", "center": list(BOX), "size": [1.0, 1.0]}]},
        "robot": {"start": [1.0, 1.0, 0.0], "radius": 0.3, "lidars": [LIDAR]},
        "sessions": [{"name": "W1", "mapping": True, "route": [[4.0, 1.0]]},
                     {"name": "W2", "changes": list(changes), "route": [[4.0, 1.0]],
                      "max_duration": 40.0}]})


def record(world):
    out = []
    for item in world.run():
        k, m = item if isinstance(item, tuple) else (0, item)
        scan = m.scan.ranges.tobytes() if isinstance(m, sim.ScanMsg) else None
        out.append((k, type(m).__name__, m.time, scan, m.true_pose))
    return out


# --- the simulator --------------------------------------------------------------------------------
def test_a_fleet_of_one_on_the_scenarios_route_is_the_single_robot():
    scn = tiny_room.tiny_room()
    route = tuple(tuple(p) for p in scn.sessions[1].route)
    fleet = FleetWorld(scn, 1, [FleetMember(scn.robot.start, route)], seed=4)
    assert record(fleet) == record(sim.World(scn, 1, seed=4))
    assert fleet.finished


def test_robots_appear_in_each_others_scans():
    scn = tiny_room.tiny_room()
    a = FleetMember(Pose2D(1.0, 1.0, 0.0), ((3.0, 1.0),))
    b = FleetMember(Pose2D(3.5, 1.0, math.pi), ((3.0, 1.0),), lidar_phase=0.05)
    world = FleetWorld(scn, 1, [a, b], seed=1)
    first = {}
    for k, msg in world.run():
        if isinstance(msg, sim.ScanMsg) and k not in first:
            first[k] = (msg, world.robot_discs()[1 - k])
        if len(first) == 2:
            break
    for k, (msg, other) in first.items():
        sensor = msg.true_pose.compose(scn.robot.lidars[0].mount)
        bare = world.scan_without_people(msg.true_pose)
        ang = msg.scan.angles() + sensor.theta
        # the beam aimed at the other robot's centre stops at its near side, short of the walls
        i = int(np.argmin(np.abs(np.angle(np.exp(1j * (ang - math.atan2(
            other[1] - sensor.y, other[0] - sensor.x)))))))
        dist = math.hypot(other[0] - sensor.x, other[1] - sensor.y) - other[2]
        assert abs(msg.scan.ranges[i] - dist) < 0.05, k
        assert bare.ranges[i] > dist + 1.0
        # the map store, told where the other robot is, hides its returns from the update
        board = FleetBoard(2, scn.robot.radius)
        board.report(1 - k, Pose2D(other[0] + 0.05, other[1], 0.0))    # a few cm off
        masked = RobotMask(None, k, board).mask(msg.scan, sensor).ranges
        assert np.isnan(masked[i]) and np.isnan(masked).sum() < 30
        assert np.array_equal(masked[~np.isnan(masked)], msg.scan.ranges[~np.isnan(masked)])
    assert first[1][0].time > first[0][0].time     # robot 1's lidar fires later
    with pytest.raises(ValueError, match="robot 1 starts .* inside robot 0"):
        FleetWorld(scn, 1, [a, FleetMember(Pose2D(1.3, 1.0, 0.0), ((3.0, 1.0),))])
    with pytest.raises(ValueError, match="inside a wall or an object"):
        FleetWorld(scn, 1, [FleetMember(Pose2D(4.0, 2.4, 0.0), ((3.0, 1.0),))])  # the pallet


def test_fleet_members_spread_along_one_loop_and_drive_it_once_round():
    scn = sim.load_scenario("scenarios/aws_small_warehouse.yaml")
    members = fleet_members(scn, 1, 4)
    assert members[0].start == scn.robot.start
    starts = np.array([[m.start.x, m.start.y] for m in members])
    assert min(np.hypot(*(starts[i] - starts[j]))
               for i in range(4) for j in range(i)) > 3.0
    for m in members:
        pts = np.vstack([[m.start.x, m.start.y], m.route])
        assert np.hypot(*(pts[-1] - pts[0])) < 1e-9               # back where it started
        assert np.hypot(*np.diff(pts, axis=0).T).sum() == pytest.approx(67.4, abs=0.2)


# --- the map store -------------------------------------------------------------------------------
def test_the_queue_releases_scans_in_scan_time_order_once_no_robot_can_precede_them():
    q = ScanQueue(2)
    q.push(0, 0.1, "a1")
    q.push(0, 0.3, "a3")
    assert q.pop_ready() == []                       # robot 1 may still send 0.05
    q.push(1, 0.05, "b0")
    q.push(1, 0.2, "b2")
    assert [x[2] for x in q.pop_ready()] == ["b0", "a1", "b2"]   # up to 0.2, robot 1's latest
    q.push(1, 0.3, "b3")
    assert [(r, t) for r, t, _ in q.pop_ready()] == [(0, 0.3), (1, 0.3)]   # ties: robot order
    q.push(0, 0.9, "a9")
    q.close(1)                                       # robot 1 is done: it holds nobody back
    assert [x[2] for x in q.pop_ready()] == ["a9"]
    q.push(0, 1.0, "a10")
    assert [x[2] for x in q.drain()] == ["a10"] and len(q) == 0
    with pytest.raises(ValueError):
        q.push(0, 0.5, "late")


def grid(rows):
    return OccupancyGrid(np.array(rows, np.int8), 0.05, (0.0, 0.0))


def test_merge_rule_by_hand():
    o, f, u = OCCUPIED, FREE, UNKNOWN
    ref = grid([[o, o, o, f, f, u]])
    a = grid([[f, o, f, o, f, f]])
    b = grid([[o, f, o, f, f, o]])
    c = grid([[o, o, f, f, f, o]])
    # union: any change from the reference wins; changes that disagree: occupied first
    assert merge_maps(ref, [a, b, c]).data.tolist() == [[f, f, f, o, f, o]]
    # vote among the robots that saw each cell 7 times or more
    seen = [np.array([[9, 9, 9, 9, 0, 9]]), np.array([[9, 9, 9, 9, 0, 9]]),
            np.array([[9, 0, 9, 9, 0, 0]])]
    merged = merge_maps(ref, [a, b, c], seen, 7).data.tolist()
    # cell 0: a says free, b and c occupied -> occupied; cell 1: a unchanged, b free (c did
    # not see it) -> tie -> the change; cell 2: a and c free -> free; cell 3: a occupied, b
    # and c free -> free; cell 5: a free, b occupied, c not a voter -> tie -> occupied
    assert merged == [[o, f, f, f, f, o]]
    assert merge_maps(ref, [ref]).data.tolist() == ref.data.tolist()


def test_each_robot_has_its_own_gate_in_front_of_the_shared_updater():
    ref = grid(np.pad(np.zeros((76, 76), np.int8), 2, constant_values=100).tolist())
    shared = shared_updater(ref)
    gates = [SharedGate(shared), SharedGate(shared)]
    with pytest.raises(ValueError, match="gate_confirm needs a shared updater made with it"):
        SharedGate(shared, UpdaterConfig(gate_confirm=True))
    from onboard.pipeline import warm_up

    scans = []
    warm_up(lambda g: _Recorder(scans))          # six scans of a walled room, moving 0.1 m each
    statuses = {0: [], 1: []}
    for k, (scan, pose) in enumerate(scans):
        for r, gate in enumerate(gates):
            # robot 0 moves with the scans, robot 1 stands still at the first pose
            odom = pose if r == 0 else scans[0][1]
            statuses[r].append(gate.process(scan, pose, odometry=odom).status)
    assert statuses[1][0] is ScanStatus.PROCESSED
    assert set(statuses[1][1:]) == {ScanStatus.GATED}          # it has not moved
    assert statuses[0].count(ScanStatus.PROCESSED) >= 2        # the other still gets through
    assert shared.stats["processed"] == sum(s.count(ScanStatus.PROCESSED)
                                            for s in statuses.values())


def test_a_robot_held_back_confirms_the_map_in_the_shared_updater():
    """With gate_confirm (the robot profile's), a robot standing still gives its first held-back
    scan's unchanged flags to the shared updater, once until a new view, and no change."""
    from onboard.pipeline import warm_up

    ref = grid(np.pad(np.zeros((76, 76), np.int8), 2, constant_values=100).tolist())
    config = UpdaterConfig.profile("robot")
    shared = shared_updater(ref, config)
    gate = SharedGate(shared, config)
    scans = []
    warm_up(lambda g: _Recorder(scans))
    reports = [gate.process(scan, pose, odometry=scans[0][1]) for scan, pose in scans]
    assert reports[0].status is ScanStatus.PROCESSED
    held = reports[1:]
    assert all(r.status is ScanStatus.GATED and r.changed_flags == 0 for r in held)
    # (the scans themselves were taken 0.1 m apart: the later ones hit a few cells the first
    # did not)
    assert held[0].unchanged_flags > 100
    assert all(r.unchanged_flags < 0.2 * held[0].unchanged_flags for r in held[1:]), \
        [r.unchanged_flags for r in held]


class _Recorder:
    """A stand-in pipeline that keeps the scans ``warm_up`` gives it."""

    def __init__(self, out):
        self.out = out

    def step(self, scan, mount, odometry=None, pose=None):
        self.out.append((scan, pose.compose(mount)))


# --- a fleet session ------------------------------------------------------------------------------
def box_session(mode, store=None, commit_interval=10.0, changes=({"remove": "box"},)):
    scn = two_rooms(changes)
    reference = sim.World(scn, 0).ground_truth()       # M1: the box still there
    west = FleetMember(scn.robot.start, ((4.0, 1.0), (1.5, 1.0)))
    east = FleetMember(Pose2D(11.0, 3.5, math.pi), ((7.0, 3.5), (7.0, 2.5), (11.0, 2.5)),
                       lidar_phase=0.05)
    seeds = session_seeds(scn.seed, 2)[1]
    world = FleetWorld(scn, 1, [west, east], seeds["world"])
    options = FleetOptions(robots=2, mode=mode, progress=False, store=store,
                           commit_interval=commit_interval, poll_interval=3.0,
                           updater_config=UpdaterConfig(gate_min_distance=0.15))
    fs = FleetSession(scn, 1, world, reference, seeds["localizer"], options)
    for k, msg in world.run():
        fs.arrive(k, msg)
    fs.finish()
    box = np.zeros(reference.shape, bool)
    row, col = reference.world_to_cell(np.array([BOX[0]]), np.array([BOX[1]]))
    box[int(row[0]) - 12:int(row[0]) + 13, int(col[0]) - 12:int(col[0]) + 13] = True
    return fs, box & (reference.data == OCCUPIED)


@pytest.mark.parametrize("mode", ["shared", "per-robot"])
def test_the_fleets_map_frees_a_box_only_one_robot_saw(mode):
    fs, box = box_session(mode)
    assert box.sum() > 30
    times = [t for t, _ in fs.handled]
    assert times == sorted(times) and {k for _, k in fs.handled} == {0, 1}
    updated, row = fs.result()
    assert (updated.data[box] == FREE).mean() > 0.5
    assert row["precision"] > 0.9 and row["latency_median_s"] is not None
    if mode == "per-robot":
        west, east = (r.updater.updated_map().data for r in fs.robots)
        assert (west[box] == FREE).sum() == 0            # the west robot never saw it
        assert (east[box] == FREE).mean() > 0.5


def replayed_site(store) -> np.ndarray:
    """The site map the merges promise, computed without them: every robot's own version's
    changes against the version it started from, applied in commit order on the first map,
    the last change of a cell winning."""
    log = store.log()
    site = store.get(log[0].number).data.copy()
    for v in log[1:]:
        if v.merge_parent is None:
            before, after = store.get(v.parent).data, store.get(v.number).data
            site[before != after] = after[before != after]
    return site


def test_robots_committing_to_a_store_share_each_others_changes(tmp_path):
    """The store mode: the east robot frees the box, the west robot never sees it; both commit
    every 10 s to one store, which merges them, and the west robot takes up the merged
    versions."""
    from mapstore import open_store

    path = str(tmp_path / "site.db")
    fs, box = box_session("store", store=path, commit_interval=4.0, changes=(
        {"remove": "box"}, {"add": {"id": "crate", "center": list(CRATE), "size": [0.6, 0.6]}}))
    updated, row = fs.result()
    assert (updated.data[box] == FREE).mean() > 0.5
    crate = near_point(updated, CRATE, 6)
    assert (updated.data[crate] == OCCUPIED).sum() >= 10        # the west robot's crate
    assert row["commits"] >= 2 and row["merges"] >= 1 and row["precision"] > 0.9, row
    west = fs.robots[0]
    with open_store(path) as store:
        assert np.array_equal(store.get(store.latest()).data, updated.data)
        assert np.array_equal(replayed_site(store), updated.data)
        robots = {v.meta.get("robot") for v in store.log() if v.merge_parent is None}
        assert {"robot1", "robot2"} <= robots
        # the west robot's own map never freed the box; the version it goes on from has it
        assert (store.get(west.version).data[box] == FREE).mean() > 0.5
    assert (west.updater.updated_map().data[box] == FREE).mean() > 0.5
    east = fs.robots[1]
    assert (east.updater.updated_map().data[crate] == OCCUPIED).sum() >= 10
    with pytest.raises(ValueError, match="--store goes with the store mode"):
        FleetOptions(mode="shared", store=path).check()
    with pytest.raises(ValueError, match="the store mode needs a store"):
        FleetOptions(mode="store").check()


@pytest.mark.slow
def test_a_quick_fleet_run_in_the_warehouse(tmp_path):
    record = run_fleet("aws_small_warehouse", FleetOptions(robots=2, quick=True, sessions=2,
                                                           progress=False), tmp_path)
    (row,) = record["sessions"]
    assert row["world_finished"] and row["recall"] > 0.5 and row["precision"] > 0.9
    assert (tmp_path / "fleet.json").exists() and (tmp_path / "maps" / "M_W2.yaml").exists()
    assert "shared" in format_table(record["sessions"])


def test_the_command_line_prints_the_table_and_writes_the_run(tmp_path, capsys):
    from mapupdate import main

    path = tiny_room.write_tiny_room(tmp_path / "tiny.yaml")
    assert main(["fleet", "--scenario", str(path), "--robots", "2", "--mode", "per-robot",
                 "--no-progress", "--out", str(tmp_path / "run")]) == 0
    out = capsys.readouterr().out
    assert "| 2 | per-robot (vote) | W2 |" in out
    record = json.loads((tmp_path / "run" / "fleet.json").read_text())
    assert record["robots"] == 2 and record["sessions"][0]["world_finished"]
    assert main(["fleet", "--scenario", str(path), "--robots", "2", "--no-progress",
                 "--store", str(tmp_path / "site.db")]) == 0
    row = next(line for line in capsys.readouterr().out.splitlines() if "| store |" in line)
    commits = int(row.strip("| ").split(" | ")[-3])
    from mapstore import open_store
    with open_store(str(tmp_path / "site.db")) as store:     # W1's map, then the commits
        assert sum(v.merge_parent is None for v in store.log()) == 1 + commits
    assert main(["fleet", "--scenario", str(path), "--robots", "9", "--no-progress"]) == 2
    assert capsys.readouterr().err.strip() == \
        "mapupdate fleet: error: robots must be a whole number in 1..8, got 9"
