"""A fleet on one map store: live ROS 2 nodes in one graph, in the namespaces robot1, robot2
and robot3 (each with its /tf and /tf_static remapped into its namespace, as a multi-robot
bringup does), one recording each, one PostgreSQL store. Each robot drove the synthetic room
in which another of its three boxes is gone; the three sessions commit from the same version,
so the store merges the second and the third with what was committed before them, and every
node ends serving the site's map with all three boxes gone. Then two robots change the same
cells in different ways (unknown floor seen empty by one, with a new box by the other): the
one that committed last decides.

The expectation is made apart from the store: each recording's map as ``mapupdate update``
makes it alone, its changed cells laid on the shared map in the order the store took the
commits (the three boxes' change sets are disjoint, so there the order does not matter).

The commits are made to overlap: the test holds the store's write lock (the row the store
locks, docs/map_store.md) until every node's commit waits for it. A node takes up a newer
approved version at its next poll with fresh buffers, so a session not yet committed when
another robot's lands is dropped at that poll, not merged: commits a poll period apart would
never merge. Skipped, with the reason, where ROS 2, its tf messages, PostgreSQL or psycopg
in .venv-ros2 cannot be had."""

from __future__ import annotations

import functools
import json
import math
import queue
import subprocess
import threading
import time

import numpy as np
import pytest

from gridmap import OCCUPIED, UNKNOWN, OccupancyGrid, Pose2D, Scan, load_map, save_map
from mapupdate import main
from robotlogs.records import OdomRecord, ScanRecord, TransformRecord
from robotlogs.rosbag import write_bag

import postgres_tools
import ros2_tools
import synthetic_room as room


@functools.cache
def missing_psycopg() -> str:
    """Why the nodes cannot reach a PostgreSQL store ('' when they can): psycopg is the
    ``store`` extra, which ros/install-ros2.sh does not install into .venv-ros2."""
    if ros2_tools.missing_tf():
        return ros2_tools.missing_tf()
    p = subprocess.run([ros2_tools.PYTHON, "-c", "import psycopg"], capture_output=True,
                       text=True, timeout=120)
    if p.returncode:
        return ("psycopg is not installed in .venv-ros2, so the nodes cannot open a "
                "postgresql:// store (.venv-ros2/bin/pip install 'psycopg[binary]')")
    return ""


pytestmark = pytest.mark.skipif(bool(missing_psycopg()), reason=missing_psycopg() or "-")

ROBOTS = ("robot1", "robot2", "robot3")
Q = room.RES / 4            # faces a quarter cell off the grid, as synthetic_hall's


def _box(x: float, y: float, side: float = 0.6) -> room.Rect:
    return room.Rect(x + Q, y + Q, x + side + Q, y + side + Q)


# the room's boxes; robotN drove the room with the N-th one gone
BOXES = {"robot1": _box(1.6, 1.6), "robot2": _box(8.8, 1.6), "robot3": _box(5.2, 8.9)}
MOUNT = Pose2D(0.2, 0.0, 0.0)
EPOCH = 1_700_000_000.0     # [s] the recordings' clock at their start (not 0: tf's "latest")
SECONDS, SPEED = 20.0, 1.0  # one lap of the 3 m circle round the room's middle, 200 scans
RATE = 2.0                  # times real time: the three at once, 10 s
POLL = 1.0                  # [s] store_poll_period


def recording(path, shapes, seed: int) -> int:
    """A robot's drive round the room among ``shapes`` (the walls added), as a ROS 2 bag: the
    mount on /tf_static; per scan the odometry (/odom, odom -> base_link), the localisation
    (map -> odom, the pose with synthetic_room's 2 cm / 1 deg noise) and the 270 deg scan
    cast from the true pose. Returns the number of scans."""
    shapes = room.room_walls() + list(shapes)
    fov, beams = math.radians(270.0), 541
    angle_min, inc = -fov / 2, fov / (beams - 1)
    angles = angle_min + inc * np.arange(beams)
    odom_start = Pose2D(1.0, -2.0, 0.3)             # the odometry's frame is not the map's
    records = [TransformRecord(EPOCH, "base_link", "laser", MOUNT, static=True)]
    first = None
    for true, noisy, t in room.Drive(seconds=SECONDS, speed=SPEED, seed=seed).steps():
        first = true if first is None else first
        t += EPOCH
        odom = odom_start.compose(first.inverse().compose(true))
        ranges = room.cast(shapes, true.compose(MOUNT), angles, 20.0).astype(np.float32)
        records += [OdomRecord(t, odom), TransformRecord(t, "odom", "base_link", odom),
                    TransformRecord(t, "map", "odom", noisy.compose(odom.inverse())),
                    ScanRecord(t, Scan(ranges, angle_min, inc, 0.05, 20.0, t))]
    write_bag(path, records, "ros2")
    return sum(isinstance(r, ScanRecord) for r in records)


def sessions_alone(root, base: OccupancyGrid, worlds: dict) -> dict:
    """``base`` as ``root/site.yaml``, and for each robot of ``worlds`` (its shapes) its
    recording and the map `mapupdate update` makes of that recording alone."""
    save_map(base, root / "site.yaml")
    out = {"root": root, "base": load_map(root / "site.yaml"), "bags": {}, "alone": {},
           "scans": {}}
    for k, (robot, shapes) in enumerate(worlds.items()):
        bag = root / f"{robot}_bag"
        out["scans"][robot] = recording(bag, shapes, seed=k + 1)
        assert main(["update", "--map", str(root / "site.yaml"), "--log", str(bag), "--out",
                     str(root / f"{robot}_alone.yaml"), "--no-progress"]) == 0
        out["bags"][robot] = bag
        out["alone"][robot] = load_map(root / f"{robot}_alone.yaml").data
    return out


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """The shared map (the room, its three boxes); each robot's recording, its own box gone,
    and the map `mapupdate update` makes of it alone."""
    base = room.rasterise(room.room_walls() + list(BOXES.values()))
    worlds = {r: [b for other, b in BOXES.items() if other != r] for r in ROBOTS}
    return sessions_alone(tmp_path_factory.mktemp("fleet"), base, worlds)


# floor the shared map leaves unknown in the room's middle; robot1 saw it empty, robot2 saw a
# new box standing in it
PATCH = room.Rect(4.8, 4.8, 6.2, 6.2)
NEW_BOX = _box(5.2, 5.2)


@pytest.fixture(scope="module")
def overlap(tmp_path_factory):
    """The shared map with the unknown patch; robot1's recording of it empty, robot2's with
    the new box in it, and the maps `mapupdate update` makes of them alone."""
    base = room.rasterise(room.room_walls() + list(BOXES.values()))
    data = base.data.copy()
    data[room.cells_of(PATCH)] = UNKNOWN
    base = base.with_data(data)
    worlds = {"robot1": list(BOXES.values()), "robot2": [*BOXES.values(), NEW_BOX]}
    return sessions_alone(tmp_path_factory.mktemp("overlap"), base, worlds)


@pytest.fixture(scope="module")
def postgres():
    srv, why = postgres_tools.server()
    if srv is None:
        pytest.skip(why)
    yield srv
    srv.stop()


@pytest.fixture(scope="module")
def graph(tmp_path_factory):
    g = ros2_tools.Graph(tmp_path_factory.mktemp("ros2_fleet"))
    yield g
    g.close()


# the recording player (ros/tools/play.py) in a robot's namespace, as its --namespace does
PLAY_IN_NAMESPACE = """
import importlib.util, sys
bag, namespace, rate, tools = sys.argv[1:5]
spec = importlib.util.spec_from_file_location("play", f"{tools}/play.py")
play = importlib.util.module_from_spec(spec)
spec.loader.exec_module(play)
sys.exit(play.main(bag, float(rate), "tf", namespace=namespace))
"""

# the operator: one client per node's ~/commit; each request sent when its robot's name
# comes on stdin, all answers printed together
COMMITS = """
import json, queue, sys, threading, time
import rclpy
from std_srvs.srv import Trigger
names = sys.argv[1:]
rclpy.init()
node = rclpy.create_node("fleet_operator")
clients = {n: node.create_client(Trigger, f"/{n}/map_updater/commit") for n in names}
for n, c in clients.items():
    if not c.wait_for_service(timeout_sec=60):
        raise SystemExit(f"no service /{n}/map_updater/commit within 60 s")
end = time.monotonic() + 1.0          # the replies' side of the match (best effort)
while time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.1)
print("ready", flush=True)
lines = queue.Queue()
threading.Thread(target=lambda: [lines.put(x.strip()) for x in sys.stdin], daemon=True).start()
futures, end = {}, time.monotonic() + 150
while len(futures) < len(names) or not all(f.done() for f in futures.values()):
    if time.monotonic() > end:
        raise SystemExit(f"commits sent {list(futures)}, unanswered after 150 s: "
                         f"{[n for n, f in futures.items() if not f.done()]}")
    while not lines.empty():
        n = lines.get()
        futures[n] = clients[n].call_async(Trigger.Request())
    rclpy.spin_once(node, timeout_sec=0.05)
print(json.dumps({n: {"success": f.result().success, "message": f.result().message}
                  for n, f in futures.items()}), flush=True)
"""

# waits until each node's /diagnostics holds the wanted values and, given a map, its latched
# map_updated is that map; prints what it saw of each
WATCH = """
import json, sys, time
import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import OccupancyGrid
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
want, expected, timeout = json.loads(sys.argv[1]), sys.argv[2], float(sys.argv[3])
expected = np.load(expected) if expected else None
rclpy.init()
node = rclpy.create_node("fleet_watch")
health, maps = {}, {}

def on_diagnostics(m):
    for s in m.status:
        health[s.name] = {v.key: v.value for v in s.values}

def on_map(ns, m):
    maps[ns] = np.asarray(m.data, np.int8).reshape(m.info.height, m.info.width)

node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 30)
latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
for ns in want:
    node.create_subscription(OccupancyGrid, f"/{ns}/map_updated",
                             lambda m, ns=ns: on_map(ns, m), latched)

def seen(ns):
    h = health.get(f"/{ns}/map_updater: health", {})
    out = {"health": {k: h.get(k) for k in want[ns]}, "ok": all(
        h.get(k) == v for k, v in want[ns].items())}
    if expected is not None:
        got = maps.get(ns)
        out["map_cells_off"] = None if got is None else int(
            (got != expected).sum()) if got.shape == expected.shape else f"shape {got.shape}"
        out["ok"] = out["ok"] and out["map_cells_off"] == 0
    return out

t0 = time.monotonic()
while time.monotonic() < t0 + timeout and not all(seen(ns)["ok"] for ns in want):
    rclpy.spin_once(node, timeout_sec=0.1)
print(json.dumps({"seconds": round(time.monotonic() - t0, 2),
                  "nodes": {ns: seen(ns) for ns in want}}))
"""


def watch(graph, want: dict, expected_path="", timeout: float = 60.0) -> dict:
    out = graph.script(WATCH, json.dumps(want), expected_path, timeout, timeout=timeout + 60)
    return json.loads(out.strip().splitlines()[-1])


def _lines(stream) -> queue.Queue:
    """The lines of ``stream`` as they come, then None at its end."""
    q: queue.Queue = queue.Queue()

    def read():
        for line in stream:
            q.put(line)
        q.put(None)

    threading.Thread(target=read, daemon=True).start()
    return q


def _next_line(q: queue.Queue, timeout: float, what: str, log) -> str:
    try:
        line = q.get(timeout=timeout)
    except queue.Empty:
        raise TimeoutError(f"{what}: nothing within {timeout} s; the operator's log: "
                           f"{log.read_text()[-2000:]}") from None
    if line is None:
        raise AssertionError(f"{what}: the operator ended; its log: {log.read_text()[-2000:]}")
    return line


def commit_all_at_once(graph, url: str, order) -> dict:
    """Each node's ~/commit, sent in ``order`` while the test holds the store's write lock;
    each is sent once the one before it waits for the lock, and the lock is let go when all
    wait: every commit is made from the version its node started from, before any node's
    poll could take up another's (the first in ``order`` lands first; the others find the
    latest moved, plan again and land in the order they get the lock back). The nodes'
    answers."""
    import psycopg

    log = graph.folder / "operator.log"
    with open(log, "w") as err:
        operator = subprocess.Popen([str(ros2_tools.PYTHON), "-c", COMMITS, *order],
                                    env=graph.env, cwd=graph.folder, text=True,
                                    stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=err,
                                    start_new_session=True)
    graph.procs.append(operator)
    out = _lines(operator.stdout)
    assert _next_line(out, 120, "the operator's clients finding the commit services",
                      log).strip() == "ready"
    with psycopg.connect(url, autocommit=True) as watcher, psycopg.connect(url) as holder:
        holder.execute("SELECT value FROM mapstore_info WHERE key = 'schema' FOR UPDATE")

        def waiting() -> int:
            return watcher.execute(
                "SELECT count(*) FROM pg_stat_activity WHERE datname = current_database() "
                "AND wait_event_type = 'Lock'").fetchone()[0]

        for k, robot in enumerate(order, 1):
            operator.stdin.write(robot + "\n")
            operator.stdin.flush()
            ros2_tools.wait_until(lambda: waiting() >= k, 60,
                                  f"{robot}'s commit waiting for the store's write lock "
                                  f"({k} waiting)")
        holder.rollback()                       # the lock let go: the commits land in turn
    answers = json.loads(_next_line(out, 180, "the nodes' answers to commit", log))
    operator.wait(30)
    return answers


def new_store(postgres, base: OccupancyGrid) -> str:
    """A new PostgreSQL store holding the site's map as v1, approved, review off."""
    from mapstore import open_store

    url = postgres.new_database()
    with open_store(url, create=True) as store:
        store.set_require_approval(False)
        assert store.commit(base, None, {"robot": "site", "method": "import"},
                            status="approved") == 1
    return url


def start_nodes(graph, url: str, robots) -> dict:
    """A node per robot in its namespace, on the store, its /tf and /tf_static remapped into
    the namespace; each up and active."""
    nodes = {r: graph.node(
        "--autostart", "--ros-args", "-r", f"__ns:=/{r}", "-r", "/tf:=tf", "-r",
        "/tf_static:=tf_static", "-p", f"store:={url}", "-p", f"robot_name:={r}", "-p",
        f"store_poll_period:={POLL}", "-p", "publish_period:=0.5", "-p", "tf_timeout:=2.0",
        "-p", f"save_path:={graph.folder / (r + '.yaml')}", name=r) for r in robots}
    for r in robots:                                     # a cold numba cache compiles
        graph.wait_for_service(f"/{r}/map_updater/get_state", timeout=180)
    return nodes


def play_at_once(graph, sessions: dict) -> None:
    """Every robot's recording into its namespace at the same time; done when each node has
    received every scan of its recording."""
    robots = list(sessions["bags"])
    players = [graph.start(["-c", PLAY_IN_NAMESPACE, sessions["bags"][r], r, RATE,
                            ros2_tools.PLAY.parent], f"play-{r}") for r in robots]
    end = time.monotonic() + 180
    for r, p in zip(robots, players):
        try:
            code = p.wait(max(1.0, end - time.monotonic()))
        except subprocess.TimeoutExpired:
            raise TimeoutError(f"{r}'s recording was not played within 180 s") from None
        assert code == 0, graph.log(f"play-{r}")[-2000:]
    seen = watch(graph, {r: {"scans_received": str(sessions["scans"][r])} for r in robots},
                 timeout=30)
    assert all(n["ok"] for n in seen["nodes"].values()), \
        f"a node did not receive its whole recording within 30 s: {seen}"


def site_map(base: np.ndarray, alone: dict, order) -> np.ndarray:
    """What the merges promise, made without the store: the shared map with each robot's own
    changed cells laid on it in the order the store took the commits (a cell changed by two,
    differently, goes to the later)."""
    out = base.copy()
    for r in order:
        changed = alone[r] != base
        out[changed] = alone[r][changed]
    return out


def store_state(url: str) -> dict:
    from mapstore import open_store

    with open_store(url) as store:
        log, latest = store.log(), store.latest()
        sessions = [v for v in log if v.meta.get("source") == "live node"]
        return {"log": log, "latest": latest, "site": store.get(latest).data,
                "sessions": sessions, "merges": [v for v in log if v.merge_parent is not None],
                "maps": {v.meta["robot"]: store.get(v.number).data for v in sessions}}


def check_sessions(state: dict, sessions: dict) -> list:
    """Each robot's session as its node committed it, from v1: the map `mapupdate update`
    makes of its recording alone. The robots in the order the store took their commits."""
    order = [v.meta["robot"] for v in state["sessions"]]
    assert sorted(order) == sorted(sessions["bags"]), order
    assert all(v.parent == 1 for v in state["sessions"]), \
        [(v.number, v.parent) for v in state["sessions"]]
    for r in order:
        off = int((state["maps"][r] != sessions["alone"][r]).sum())
        assert off == 0, f"{r}'s session differs from `mapupdate update` in {off} cells"
    return order


def check_served(graph, nodes: dict, version: int, expected: np.ndarray) -> None:
    """Every node serves ``version``, whose map is ``expected``, within a few poll periods,
    then stops cleanly."""
    np.save(graph.folder / f"v{version}.npy", expected)
    seen = watch(graph, {r: {"store_version": str(version)} for r in nodes},
                 graph.folder / f"v{version}.npy", timeout=10 * POLL)
    assert all(n["ok"] for n in seen["nodes"].values()), \
        f"not every node serves v{version} (the site's map) within {10 * POLL:g} s: {seen}"
    for r, node in nodes.items():
        assert node.poll() is None and graph.stop(node) == 0, graph.log(r)[-2000:]
        assert "Traceback" not in graph.log(r)


def test_three_robots_commit_at_once_and_every_node_serves_the_merged_site_map(
        graph, fleet, postgres):
    base = fleet["base"].data
    # each robot's session alone changes only its own box's cells: three disjoint sets
    changed = {r: fleet["alone"][r] != base for r in ROBOTS}
    for r in ROBOTS:
        assert changed[r].sum() > 100 and not (changed[r] & ~room.cells_of(BOXES[r])).any(), r
    for a in ROBOTS:
        for b in ROBOTS:
            assert a == b or not (changed[a] & changed[b]).any(), (a, b)

    url = new_store(postgres, fleet["base"])
    nodes = start_nodes(graph, url, ROBOTS)
    play_at_once(graph, fleet)
    # the three commits at once, from v1, robot1's first; robot2's and robot3's come back
    # merged, and their nodes go on from the merge. robot1's waits longest for the lock and
    # lands first; the other two found the latest moved and plan again, so either may be next
    answers = commit_all_at_once(graph, url, ROBOTS)
    assert all(a["success"] for a in answers.values()), answers
    state = store_state(url)
    order = check_sessions(state, fleet)
    assert order[0] == "robot1", order
    assert answers["robot1"]["message"] == "committed v2, the reference now", answers
    assert "committed v3, merged with the site's map as v4" in answers[order[1]]["message"], \
        (order, answers)
    assert "committed v5, merged with the site's map as v6" in answers[order[2]]["message"], \
        (order, answers)
    # two merges (parent, the version merged in), without conflicts
    assert [(v.number, v.parent, v.merge_parent) for v in state["merges"]] == \
        [(4, 2, 3), (6, 4, 5)]
    assert all(v.meta["cells"]["conflicts"] == 0 for v in state["merges"])
    assert state["latest"] == 6 and state["log"][-1].status == "approved"
    expected = site_map(base, fleet["alone"], order)
    off = int((state["site"] != expected).sum())
    assert off == 0, f"the store's latest v6 differs from the expected site map in {off} cells"
    for r in ROBOTS:                                     # every robot's box gone
        box = room.cells_of(BOXES[r])
        assert (state["site"][box] != base[box]).all()
    # the last to commit serves v6 at once (its commit's merge), the others from their next
    # poll
    check_served(graph, nodes, 6, expected)


def test_a_cell_two_robots_changed_differently_goes_to_the_one_that_committed_last(
        graph, overlap, postgres, tmp_path):
    """robot1 saw the unknown patch empty, robot2 a new box in it: the box's faces robot2
    saw occupied, robot1 free. robot2 commits last, so they are occupied in the site's map;
    the patch's other cells, free on both sides, are taken once."""
    base = overlap["base"].data
    one, two = overlap["alone"]["robot1"], overlap["alone"]["robot2"]
    patch = room.cells_of(PATCH)
    assert not ((one != base) & ~patch).any() and not ((two != base) & ~patch).any()
    conflicts = (one != base) & (two != base) & (one != two)
    assert conflicts.sum() > 20 and (two[conflicts] == OCCUPIED).all()

    # a graph of its own: a node the other test left behind (had it failed) would share
    # these namespaces
    own = ros2_tools.Graph(tmp_path, other_than=graph)
    try:
        url = new_store(postgres, overlap["base"])
        nodes = start_nodes(own, url, ("robot1", "robot2"))
        play_at_once(own, overlap)
        answers = commit_all_at_once(own, url, ("robot1", "robot2"))
        assert answers["robot1"]["message"] == "committed v2, the reference now", answers
        assert "committed v3, merged with the site's map as v4" in answers["robot2"]["message"]

        state = store_state(url)
        assert check_sessions(state, overlap) == ["robot1", "robot2"]
        (merge,) = state["merges"]
        assert (merge.number, merge.parent, merge.merge_parent) == (4, 2, 3)
        assert merge.meta["conflicts_to"] == "theirs"       # robot2's session, committed last
        assert merge.meta["cells"]["conflicts"] == int(conflicts.sum())
        expected = site_map(base, overlap["alone"], ("robot1", "robot2"))
        assert (expected[conflicts] == OCCUPIED).all()
        off = int((state["site"] != expected).sum())
        assert off == 0, f"the store's latest v4 differs from the expected site map in {off} cells"
        check_served(own, nodes, 4, expected)
    finally:
        own.close()


def test_a_robot_committing_polls_after_another_keeps_its_session(graph, fleet, postgres,
                                                                  tmp_path):
    """robot1 commits; robot2, its session not committed yet, takes up robot1's version at its
    next poll and commits several poll periods later. Its box is not lost: its node laid its
    uncommitted changes on the newer version, and its commit, made on it, holds both boxes
    without a merge."""
    from mapstore import open_store

    base = fleet["base"].data
    own = ros2_tools.Graph(tmp_path, other_than=graph)
    try:
        url = new_store(postgres, fleet["base"])
        robots = ("robot1", "robot2")
        nodes = start_nodes(own, url, robots)
        play_at_once(own, {"bags": {r: fleet["bags"][r] for r in robots},
                           "scans": {r: fleet["scans"][r] for r in robots}})
        log = own.folder / "operator.log"
        with open(log, "w") as err:
            operator = subprocess.Popen([str(ros2_tools.PYTHON), "-c", COMMITS, *robots],
                                        env=own.env, cwd=own.folder, text=True,
                                        stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                        stderr=err, start_new_session=True)
        own.procs.append(operator)
        out = _lines(operator.stdout)
        assert _next_line(out, 120, "the operator's clients", log).strip() == "ready"
        operator.stdin.write("robot1\n")
        operator.stdin.flush()

        def latest() -> int:
            with open_store(url) as store:
                return store.latest()
        ros2_tools.wait_until(lambda: latest() == 2, 60, "robot1's commit as v2")
        seen = watch(own, {"robot2": {"store_version": "2"}}, timeout=10 * POLL)
        assert seen["nodes"]["robot2"]["ok"], f"robot2 did not take up v2: {seen}"
        operator.stdin.write("robot2\n")
        operator.stdin.flush()
        answers = json.loads(_next_line(out, 120, "the nodes' answers to commit", log))
        operator.wait(30)
        assert answers["robot1"]["message"] == "committed v2, the reference now", answers
        assert answers["robot2"]["message"] == "committed v3, the reference now", answers
        state = store_state(url)
        assert [(v.number, v.parent, v.merge_parent) for v in state["log"]] == \
            [(1, None, None), (2, 1, None), (3, 2, None)]
        expected = site_map(base, fleet["alone"], robots)
        off = int((state["site"] != expected).sum())
        assert off == 0, f"the site's map v3 differs from both robots' sessions in {off} cells"
        check_served(own, nodes, 3, expected)
    finally:
        own.close()
