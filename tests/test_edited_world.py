"""Edited-world cases (evaluation.edited_world, ``mapupdate inject`` and ``mapupdate score``):
the ray geometry against independent computations, the placement rules, determinism, the
edited log read back at the same laser poses, scores of hand-made maps, bad input, and a real
building (aces) when its log is at hand."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from evaluation import case_folder
from evaluation import edited_world as ew
from gridmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid, Pose2D, Scan, load_map, save_map
from robotlogs import Observation, log_observations
from robotlogs import carmen
from robotlogs.records import OdomRecord, ScanRecord, TransformRecord
from robotlogs.rosbag import write_bag
from mapupdate import main

RADISH = Path(__file__).resolve().parents[2] / "shared/data/radish"
RES = 0.05
ROOM = (12.0, 9.0)                       # inner size [m] of the synthetic room, corner at 0, 0
LOOP = [(2.0, 2.0), (10.0, 2.0), (10.0, 7.0), (2.0, 7.0), (2.0, 2.25)]
FLASER = dict(angle_min=-math.pi / 2, increment=math.pi / 180, beams=180,
              range_min=carmen.RANGE_MIN, range_max=carmen.FLASER_NO_RETURN)
WIDE = dict(angle_min=-math.radians(135), increment=math.radians(1.0), beams=271,
            range_min=0.05, range_max=20.0)


# --- a synthetic room and a drive round it ------------------------------------------------------

def room_map() -> OccupancyGrid:
    """The room: free inside, walls 0.1 m thick occupied, unknown outside."""
    grid = OccupancyGrid.empty(int((ROOM[0] + 1) / RES), int((ROOM[1] + 1) / RES), RES,
                               origin=(-0.5, -0.5))
    rows, cols = np.mgrid[0:grid.height, 0:grid.width]
    x, y = grid.cell_to_world(rows, cols)
    cells = np.full(grid.shape, UNKNOWN, np.int8)
    cells[(x > -0.1) & (x < ROOM[0] + 0.1) & (y > -0.1) & (y < ROOM[1] + 0.1)] = OCCUPIED
    cells[(x > 0) & (x < ROOM[0]) & (y > 0) & (y < ROOM[1])] = FREE
    return grid.with_data(cells)


def wall_ranges(x, y, angles) -> np.ndarray:
    """Exact distance from (x, y) inside the room to its walls along each world angle."""
    dx, dy = np.cos(angles), np.sin(angles)
    with np.errstate(divide="ignore"):
        tx = np.where(dx > 0, (ROOM[0] - x) / dx, np.where(dx < 0, -x / dx, np.inf))
        ty = np.where(dy > 0, (ROOM[1] - y) / dy, np.where(dy < 0, -y / dy, np.inf))
    return np.minimum(tx, ty)


def drive(geometry=FLASER, seed=1, step=0.25, period=0.25):
    """(time, laser pose, odometry pose, scan) along the loop, odometry drifting from the
    corrected laser poses (so the log's poses are a localisation beside its odometry)."""
    rng = np.random.default_rng(seed)
    poses = []
    for (x0, y0), (x1, y1) in zip(LOOP, LOOP[1:]):
        n = int(round(math.hypot(x1 - x0, y1 - y0) / step))
        yaw = math.atan2(y1 - y0, x1 - x0)
        poses += [Pose2D(x0 + (x1 - x0) * i / n, y0 + (y1 - y0) * i / n, yaw) for i in range(n)]
    out, odom = [], Pose2D(0.5, -0.3, 0.1)
    for k, pose in enumerate(poses):
        if k:
            d = poses[k - 1].inverse().compose(pose)
            odom = odom.compose(Pose2D(d.x * 1.02, d.y + rng.normal(0, 0.002), d.theta * 0.99))
        angles = geometry["angle_min"] + geometry["increment"] * np.arange(geometry["beams"])
        r = wall_ranges(pose.x, pose.y, angles + pose.theta) + rng.normal(0, 0.01, angles.size)
        r = np.round(r, 3)
        r[rng.random(angles.size) < 0.02] = np.inf          # some beams without a return
        scan = Scan(r.astype(np.float32), geometry["angle_min"], geometry["increment"],
                    geometry["range_min"], geometry["range_max"], 100.0 + period * k)
        out.append((scan.time, pose, odom, scan))
    return out


def carmen_line(t, laser, odom, scan) -> str:
    poses = " ".join(repr(float(v)) for v in (laser.x, laser.y, laser.theta,
                                              odom.x, odom.y, odom.theta))
    if scan.angle_min == FLASER["angle_min"] and scan.beams == 180:
        r = np.where(np.isfinite(scan.ranges), scan.ranges, 81.83)
        return f"FLASER 180 {' '.join(f'{v:.3f}' for v in r)} {poses} {t!r} h {t!r}"
    r = np.where(np.isfinite(scan.ranges), scan.ranges, scan.range_max)
    fov = (scan.beams - 1) * scan.angle_increment
    return (f"ROBOTLASER1 0 {scan.angle_min!r} {fov!r} {scan.angle_increment!r} "
            f"{scan.range_max!r} 0.01 0 {scan.beams} {' '.join(f'{v:.3f}' for v in r)} 0 "
            f"{poses} 0 0 0 0 0 {t!r} h {t!r}")


def write_world(folder: Path, geometry=FLASER) -> tuple[Path, Path]:
    """The room's map and a CARMEN log of the drive in ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    save_map(room_map(), folder / "map.yaml")
    log = folder / "drive.log"
    log.write_text("\n".join(carmen_line(*s) for s in drive(geometry)) + "\n")
    return folder / "map.yaml", log


def observations(log) -> list[Observation]:
    return list(log_observations(log).observations)


def inject(out, map_path, log, *more) -> int:
    return main(["inject", "--map", str(map_path), "--log", str(log), "--out", str(out),
                 "--no-progress", *map(str, more)])


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    return write_world(tmp_path_factory.mktemp("room"))


@pytest.fixture(scope="module")
def case(world, tmp_path_factory):
    """A case of the room: 2 removed, 2 added, 1 moved, no people."""
    out = tmp_path_factory.mktemp("case") / "c"
    assert inject(out, *world, "--seed", 4, "--removed", 2, "--added", 2, "--moved", 1,
                  "--min-views", 8) == 0
    return out


# --- geometry ------------------------------------------------------------------------------------

def test_the_writer_uses_the_carmen_readers_geometry():
    assert ew.FLASER_NO_RETURN == carmen.FLASER_NO_RETURN
    assert ew.CARMEN_RANGE_MIN == carmen.RANGE_MIN


@pytest.mark.parametrize("box", [ew.Box(2.2, 0.0, 0.4, 1.0, 0.0),
                                 ew.Box(2.2, 0.0, 1.0, 0.4, math.pi / 2)])
def test_beams_crossing_an_axis_aligned_face_end_on_it(box):
    """Laser at the origin facing +x, a wall at x = 5, the box's near face at x = 2 for
    y in [-0.5, 0.5]: beams through the face end at 2 / cos(a), the others keep 5 / cos(a)."""
    a = np.radians(np.arange(-60, 61, 1.0))
    scan = Scan((5 / np.cos(a)).astype(np.float32), a[0], a[1] - a[0], 0.01, 30.0)
    got = ew.edit_scans(scan, Pose2D(0, 0, 0), [box])
    through = np.abs(2 * np.tan(a)) <= 0.5
    want = np.where(through, 2 / np.cos(a), 5 / np.cos(a))
    np.testing.assert_allclose(got, want, rtol=1e-6)
    assert through.sum() == 29


def ray_march(ox, oy, angles, box: ew.Box, reach: float, step=0.002) -> np.ndarray:
    """The first point along each ray inside the box's rectangle (corners turned by hand and
    tested with cross products), sampled every 2 mm; inf where none within ``reach``."""
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    half = [(-box.w / 2, -box.h / 2), (box.w / 2, -box.h / 2), (box.w / 2, box.h / 2),
            (-box.w / 2, box.h / 2)]
    corners = [(box.cx + c * u - s * v, box.cy + s * u + c * v) for u, v in half]
    d = np.arange(0.0, reach, step)
    px = ox + np.cos(angles)[:, None] * d
    py = oy + np.sin(angles)[:, None] * d
    inside = np.ones(px.shape, bool)
    for (x0, y0), (x1, y1) in zip(corners, corners[1:] + corners[:1]):
        inside &= (x1 - x0) * (py - y0) - (y1 - y0) * (px - x0) >= 0
    first = np.where(inside.any(axis=1), d[inside.argmax(axis=1)], np.inf)
    return first


def test_a_rotated_box_matches_a_dense_march_along_every_beam():
    sensor = Pose2D(1.0, -0.5, 0.3)
    box = ew.Box(3.1, 0.9, 1.1, 0.5, 0.6)
    n = 360
    angles = -math.pi + 2 * math.pi / n * np.arange(n)
    rng = np.random.default_rng(0)
    ranges = rng.uniform(0.5, 6.0, n)
    ranges[rng.random(n) < 0.2] = np.inf                    # no return
    ranges[5] = np.nan                                      # an invalid beam stays invalid
    scan = Scan(ranges.astype(np.float32), angles[0], angles[1] - angles[0], 0.05, 8.0)
    got = ew.edit_scans(scan, sensor, [box])
    hit = ray_march(sensor.x, sensor.y, angles + sensor.theta, box, 8.0)
    want = np.where(hit < np.asarray(scan.ranges, np.float64), hit, scan.ranges)
    assert np.isnan(got[5])
    ok = ~np.isnan(want)
    np.testing.assert_allclose(got[ok], want[ok], atol=0.01)
    with np.errstate(invalid="ignore"):
        assert ((hit < ranges) & np.isfinite(hit)).sum() >= 8   # beams ending on the box ...
        assert ((hit > ranges) & np.isfinite(hit)).sum() >= 3   # ... and nearer readings kept
        assert (np.isinf(ranges) & np.isfinite(hit)).sum() >= 1  # ... and a no-return cut


def test_a_box_beyond_the_range_limit_or_behind_a_nearer_reading_changes_nothing():
    a = np.radians(np.arange(-10, 11, 1.0))
    scan = Scan(np.full(a.size, 1.5, np.float32), a[0], a[1] - a[0], 0.01, 30.0)
    assert np.array_equal(ew.edit_scans(scan, Pose2D(0, 0, 0), [ew.Box(3, 0, 1, 1, 0)]),
                          scan.ranges)
    far = Scan(np.full(a.size, np.inf, np.float32), a[0], a[1] - a[0], 0.01, 2.0)
    assert np.isinf(ew.edit_scans(far, Pose2D(0, 0, 0), [ew.Box(3, 0, 1, 1, 0)])).all()


def test_people_are_discs_and_one_on_the_laser_is_not_seen():
    scan = Scan(np.full(3, 10.0, np.float32), -0.01, 0.01, 0.01, 30.0)
    got = ew.edit_scans(scan, Pose2D(0, 0, 0), discs=[(3.0, 0.0, 0.25)])
    np.testing.assert_allclose(got[1], 2.75, rtol=1e-6)
    np.testing.assert_allclose(got[0], 3 * math.cos(0.01) - math.sqrt(
        0.25 ** 2 - (3 * math.sin(0.01)) ** 2), rtol=1e-6)
    assert np.array_equal(ew.edit_scans(scan, Pose2D(0, 0, 0), discs=[(0.1, 0.0, 0.25)]),
                          scan.ranges)


def test_outline_and_interior_cells():
    grid = OccupancyGrid.empty(40, 40, 0.05)
    outline, interior = ew.Box(1.0, 1.0, 0.5, 0.3, 0.0).masks(grid)
    covered = outline | interior
    assert covered.sum() == 10 * 6 and interior.sum() == 8 * 4
    assert not (outline & interior).any()


@pytest.mark.parametrize("times, nominal", [
    ([0.0, 0.0, 0.0, 0.0], [0.0, 1.0, 2.0, 3.0]),
    ([5.0, 6.0, 5.5, 7.0], [0.0, 1.25, 2.5, 3.75]),     # the median of 1 s and 1.5 s
    ([5.0, 6.0, 7.0, 8.0], None)])
def test_broken_times_give_scan_order_times_a_nominal_period(times, nominal):
    t, note = ew.scan_times(times)
    if nominal is None:
        assert note is None and np.array_equal(t, times)
    else:
        assert "broken" in note
        np.testing.assert_allclose(t, nominal)


# --- placement ---------------------------------------------------------------------------------

def box_points(box: ew.Box, grow: float = 0.0, step: float = 0.01) -> np.ndarray:
    """Points filling the box grown by ``grow`` (its rectangle, corners included)."""
    u, v = np.meshgrid(np.arange(-box.w / 2 - grow, box.w / 2 + grow + 1e-9, step),
                       np.arange(-box.h / 2 - grow, box.h / 2 + grow + 1e-9, step))
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    return np.c_[box.cx + c * u.ravel() - s * v.ravel(), box.cy + s * u.ravel() + c * v.ravel()]


def rect_distance(box: ew.Box, p: np.ndarray) -> np.ndarray:
    """Distance from points to the box's rectangle, worked out by hand."""
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    u = c * (p[:, 0] - box.cx) + s * (p[:, 1] - box.cy)
    v = -s * (p[:, 0] - box.cx) + c * (p[:, 1] - box.cy)
    du, dv = np.clip(np.abs(u) - box.w / 2, 0, None), np.clip(np.abs(v) - box.h / 2, 0, None)
    return np.sqrt(du ** 2 + dv ** 2)


def boxes_of(case_dir) -> list[tuple[str, ew.Box, int]]:
    record = yaml.safe_load((Path(case_dir) / "case.yaml").read_text())
    return [(b["kind"], ew.Box(*b["centre"], *b["size"], b["yaw"]), b["views"])
            for b in record["boxes"]]


def test_boxes_lie_on_free_floor_clear_of_the_path_and_of_each_other(world, case):
    grid = load_map(world[0])
    lasers = np.array([[o.sensor.x, o.sensor.y] for o in observations(world[1])])
    boxes = boxes_of(case)
    assert [k for k, _, _ in boxes] == ["moved_from", "moved_to", "removed", "removed",
                                        "added", "added"]
    for i, (_, box, _) in enumerate(boxes):
        # the map is free under the box and 0.3 m round it: every cell holding a point within
        # 0.26 m of it (its centre within 0.26 m + half a cell's diagonal < 0.3 m)
        p = box_points(box, grow=0.26)
        p = p[rect_distance(box, p) <= 0.26]
        r, c = grid.world_to_cell(p[:, 0], p[:, 1])
        assert (grid.data[r, c] == FREE).all()
        inner = box_points(box)
        gaps = np.hypot(inner[:, None, 0] - lasers[None, :, 0],
                        inner[:, None, 1] - lasers[None, :, 1])
        assert gaps.min() >= ew.PATH_MARGIN - 1e-9
        for _, other, _ in boxes[i + 1:]:
            assert rect_distance(other, inner).min() >= ew.CLEARANCE - 2 * RES
    moved_from, moved_to = boxes[0][1], boxes[1][1]
    assert (moved_from.w, moved_from.h) == (moved_to.w, moved_to.h)


def test_every_box_is_seen_by_min_views_scans_of_the_edited_log(world, case):
    """Counted again from the files: a scan sees an added box when 3 of its edited beams end
    on the box's boundary (and were longer before), a removed one when 3 beams pass into it."""
    before, after = observations(world[1]), observations(case / "log.clf")
    for kind, box, views in boxes_of(case):
        seen = 0
        for b, a in zip(before, after):
            p = a.sensor
            angles = a.scan.angles() + p.theta
            r = a.scan.ranges.astype(np.float64)
            if kind in ("added", "moved_to"):
                end = np.c_[p.x + r * np.cos(angles), p.y + r * np.sin(angles)]
                with np.errstate(invalid="ignore"):
                    on = (box.distance(end[:, 0], end[:, 1]) < 1e-4) & ~(b.scan.ranges <= r)
            else:
                t = ray_march(p.x, p.y, angles, box, 15.0, step=0.01)
                with np.errstate(invalid="ignore"):
                    on = t < np.minimum(r, a.scan.range_max)
            seen += np.count_nonzero(on) >= ew.MIN_BEAMS
        assert seen >= 8, (kind, box)
        assert abs(seen - views) <= 2, (kind, seen, views)   # 1 cm steps of the march


def test_removed_views_count_the_scans_whose_beams_pass_through_each_outline_cell(case):
    """Counted again by marching every beam of the edited log in 1 cm steps up to its return
    less the updater's walk skip (0.15 m): the scans that pass through each outline cell of a
    removed box. Cells a march and a grid traversal see differently (a beam grazing a corner)
    are few."""
    truth = np.load(case / "truth.npz")
    outline, views = truth["removed_outline"], truth["removed_views"]
    stale = load_map(case / "stale.yaml")
    counts = np.zeros(stale.shape, int)
    for a in observations(case / "log.clf"):
        p, r = a.sensor, a.scan.ranges.astype(np.float64)
        ok = np.isfinite(r) & (r < a.scan.range_max)
        angles = a.scan.angles()[ok] + p.theta
        hit = np.zeros(stale.shape, bool)
        for reach, angle in zip(r[ok] - ew.WALK_SKIP, angles):
            d = np.arange(0.0, max(reach, 0.0), 0.01)
            rows, cols = stale.world_to_cell(p.x + d * np.cos(angle), p.y + d * np.sin(angle))
            inside = stale.contains(rows, cols)
            hit[rows[inside], cols[inside]] = True
        counts += hit & outline
    march, traversal = counts[outline], views[outline].astype(int)
    assert outline.sum() > 50 and (traversal > 0).mean() > 0.9
    # a traversal enters every cell a beam touches, a 1 cm march may step over a corner
    assert (np.abs(march - traversal) <= np.maximum(2, 0.1 * traversal)).mean() >= 0.95
    assert abs(march.sum() - traversal.sum()) <= 0.05 * traversal.sum()
    assert (views[~outline] == 0).all()
    assert (truth["removed_seen"] == (outline & (views > 0))).all()
    assert (truth["added_outline"] == (truth["added_views"] > 0)).all()


def test_the_stale_map_has_each_removed_box_drawn_as_a_slam_map_shows_it(world, case):
    ref, stale = load_map(world[0]), load_map(case / "stale.yaml")
    truth = np.load(case / "truth.npz")
    assert (stale.data[truth["removed_outline"]] == OCCUPIED).all()
    assert (stale.data[truth["removed_interior"]] == UNKNOWN).all()
    assert (ref.data[truth["removed_outline"] | truth["removed_interior"]] == FREE).all()
    changed = stale.data != ref.data
    assert np.array_equal(changed, truth["removed_outline"] | truth["removed_interior"])
    assert (ref.data[truth["added_all"]] == FREE).all() and not truth["people"].any()
    assert truth["added_outline"].any() and not (truth["added_outline"] & ~truth["added_all"]).any()
    np.testing.assert_array_equal(truth["reference"], ref.data)


def test_the_same_seed_gives_the_same_case_byte_for_byte_and_another_seed_another(world,
                                                                                   tmp_path):
    args = ("--removed", 2, "--added", 2, "--moved", 1, "--people", 2)
    for name, seed in (("a", 9), ("b", 9), ("c", 10)):
        assert inject(tmp_path / name, *world, "--seed", seed, *args) == 0
    for f in case_folder.CASE_FILES:
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes(), f
    assert (tmp_path / "a" / "log.clf").read_bytes() != (tmp_path / "c" / "log.clf").read_bytes()
    assert (tmp_path / "a" / "case.yaml").read_bytes() != \
        (tmp_path / "c" / "case.yaml").read_bytes()


def test_fewer_boxes_than_asked_are_reported_and_none_at_all_is_an_error(world, tmp_path,
                                                                        capsys):
    assert inject(tmp_path / "many", *world, "--seed", 1, "--removed", 0, "--added", 40) == 0
    out = capsys.readouterr().out
    placed = yaml.safe_load((tmp_path / "many" / "case.yaml").read_text())["placed"]["added"]
    assert 0 < placed < 40 and f"only {placed} of 40 added boxes fit" in out
    assert inject(tmp_path / "none", *world, "--seed", 1, "--min-views", 100000) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no box fits" in err
    assert not (tmp_path / "none").exists()


def test_people_walk_the_free_space_cut_into_the_scans_and_never_into_the_truth(world,
                                                                              tmp_path):
    grid = load_map(world[0])
    source = observations(world[1])
    case = ew.make_case(grid, source, 5, removed=0, added=0, people=3)
    assert len(case.people) == 3 and not case.boxes
    assert not (case.truth["added_outline"] | case.truth["removed_outline"]).any()
    assert case.truth["people"].any() and (grid.data[case.truth["people"]] == FREE).all()
    changed = 0
    for obs, pose, ranges in zip(case.observations, case.sensors, case.ranges):
        edited = ranges != obs.scan.ranges
        changed += edited.sum()
        a = obs.scan.angles()[edited] + pose.theta
        x, y = pose.x + ranges[edited] * np.cos(a), pose.y + ranges[edited] * np.sin(a)
        # every edited beam ends on the boundary of a person standing there at the scan's time
        gap = np.full(x.size, np.inf)
        for p in case.people:
            px, py = p.at(obs.time)
            gap = np.minimum(gap, np.abs(np.hypot(x - px, y - py) - p.radius))
        assert (gap < 1e-4).all()
    assert changed > 50
    speeds = [np.hypot(*np.diff(p.xy, axis=0).T) / np.diff(p.times) for p in case.people]
    moving = np.concatenate(speeds)
    assert (moving[moving > 0] >= 0.5 - 1e-9).all() and (moving <= 1.3 + 1e-9).all()
    assert (moving == 0).any()                                # standing still now and then


# --- the edited log ----------------------------------------------------------------------------

@pytest.mark.parametrize("geometry, line", [(FLASER, "FLASER"), (WIDE, "ROBOTLASER1")])
def test_update_places_every_edited_scan_at_the_original_laser_pose(geometry, line, tmp_path):
    map_path, log = write_world(tmp_path / "w", geometry)
    out = tmp_path / "case"
    assert inject(out, map_path, log, "--seed", 2, "--removed", 1, "--added", 2,
                  "--people", 1) == 0
    text = (out / "log.clf").read_text().splitlines()
    assert all(t.startswith(line + " ") for t in text[1:])
    before, after = observations(log), observations(out / "log.clf")
    case = ew.make_case(load_map(map_path), before, 2, removed=1, added=2, people=1)
    assert len(before) == len(after) == len(case.ranges)
    for b, a, r in zip(before, after, case.ranges):
        assert (a.sensor, a.odom, a.mount, a.recorded, a.time) == \
            (b.sensor, b.odom, b.mount, b.recorded, b.time)
        assert (a.scan.angle_min, a.scan.angle_increment, a.scan.range_max) == \
            (b.scan.angle_min, b.scan.angle_increment, b.scan.range_max)
        np.testing.assert_array_equal(a.scan.ranges, r)
    for name, m, lg in (("before", map_path, log), ("after", out / "stale.yaml",
                                                     out / "log.clf")):
        assert main(["update", "--map", str(m), "--log", str(lg), "--out",
                     str(tmp_path / f"{name}.yaml"), "--poses", "recorded", "--trajectory",
                     str(tmp_path / f"{name}.tum"), "--no-progress"]) == 0
    assert (tmp_path / "before.tum").read_text() == (tmp_path / "after.tum").read_text()


def test_a_bag_is_written_as_robotlaser_lines_at_its_recorded_laser_poses(tmp_path):
    mount = Pose2D(0.2, 0.0, 0.0)
    records = [TransformRecord(100.0, "base_link", "laser", mount, static=True)]
    steps = drive(WIDE)
    for t, laser, odom, scan in steps:
        robot = laser.compose(mount.inverse())
        records += [OdomRecord(t, odom), TransformRecord(t, "odom", "base_link", odom),
                    TransformRecord(t, "map", "odom", robot.compose(odom.inverse())),
                    ScanRecord(t, scan)]
    write_bag(tmp_path / "s.bag", records, "ros1")
    save_map(room_map(), tmp_path / "map.yaml")
    assert inject(tmp_path / "case", tmp_path / "map.yaml", tmp_path / "s.bag", "--seed", 3,
                  "--removed", 1, "--added", 1) == 0
    after = observations(tmp_path / "case" / "log.clf")
    before = observations(tmp_path / "s.bag")
    assert len(after) == len(before)
    for b, a in zip(before, after):
        want = b.recorded.compose(b.mount)
        assert np.allclose(a.sensor.as_array(), want.as_array(), atol=1e-9)
        assert a.scan.beams == 271 and a.scan.angle_increment == b.scan.angle_increment


# --- scoring -----------------------------------------------------------------------------------

def scores(case_dir, map_path, tmp_path, capsys) -> dict:
    out = tmp_path / "scores.json"
    out.unlink(missing_ok=True)
    assert main(["score", str(case_dir), str(map_path), "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "removed_freed" in printed and "added_drawn" in printed
    return json.loads(out.read_text())


def test_the_stale_map_itself_frees_and_draws_nothing(case, tmp_path, capsys):
    s = scores(case, case / "stale.yaml", tmp_path, capsys)
    assert s["removed_freed"] == 0 and s["added_drawn"] == 0
    assert s["false_occupied"] == s["walls_freed"] == s["ghosts"] == 0
    assert s["removed_outline_cells"] > 0 and s["added_outline_cells"] > 0


def test_a_map_mended_by_hand_from_the_boxes_scores_full_marks(world, case, tmp_path, capsys):
    """Free every cell within a cell of a removed box and occupy the cells just inside each
    added box's boundary, from the boxes of case.yaml alone."""
    stale = load_map(case / "stale.yaml")
    rows, cols = np.mgrid[0:stale.height, 0:stale.width]
    x, y = stale.cell_to_world(rows, cols)
    cells = stale.data.copy()
    for kind, box, _ in boxes_of(case):
        d = box.distance(x, y)
        if kind in ("removed", "moved_from"):
            cells[d <= RES] = FREE
        else:
            lx, ly = box.local(x, y)
            depth = np.minimum(box.w / 2 - np.abs(lx), box.h / 2 - np.abs(ly))
            cells[(d == 0) & (depth <= RES * math.sqrt(2))] = OCCUPIED
    save_map(stale.with_data(cells), tmp_path / "mended.yaml")
    s = scores(case, tmp_path / "mended.yaml", tmp_path, capsys)
    assert s["removed_freed"] == 1 and s["added_drawn"] == 1
    assert s["walls_freed"] == 0 and s["ghosts"] == 0 and s["false_occupied"] == 0
    # and a wall freed, a cell drawn in the open: counted
    cells[tuple(np.argwhere(stale.data == OCCUPIED)[0])] = FREE
    cells[int(4.5 / RES), int(6.0 / RES)] = OCCUPIED
    save_map(stale.with_data(cells), tmp_path / "worse.yaml")
    s = scores(case, tmp_path / "worse.yaml", tmp_path, capsys)
    assert s["walls_freed"] == 1 and s["false_occupied"] == 1


# --- bad input ---------------------------------------------------------------------------------

def one_line_error(capsys, *words) -> None:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("mapupdate "), err
    for w in words:
        assert w in err, err


def snapshot(*paths) -> dict:
    return {p: p.read_bytes() for p in paths}


def test_bad_input_is_one_line_exit_2_and_writes_nothing(world, case, tmp_path, capsys):
    map_path, log = world
    inputs = snapshot(map_path, map_path.with_suffix(".pgm"), log)
    assert inject(tmp_path / "a", tmp_path / "nope.yaml", log, "--seed", 1) == 2
    one_line_error(capsys, "nope.yaml")
    full = tmp_path / "full"
    full.mkdir()
    (full / "keep.txt").write_text("mine")
    assert inject(full, map_path, log, "--seed", 1) == 2
    one_line_error(capsys, "not empty")
    assert [p.name for p in full.iterdir()] == ["keep.txt"]
    assert inject(log, map_path, log, "--seed", 1) == 2
    one_line_error(capsys, "is the log")
    assert inject(map_path.with_suffix(".pgm"), map_path, log, "--seed", 1) == 2
    one_line_error(capsys, "is the map")
    assert inject(tmp_path / "b", map_path, log, "--seed", 1, "--added", -1) == 2
    one_line_error(capsys, "added")
    assert inject(tmp_path / "b", map_path, log, "--seed", -1) == 2
    one_line_error(capsys, "seed")
    assert snapshot(*inputs) == inputs
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_a_log_without_corrected_poses_is_refused(tmp_path, capsys):
    records = [TransformRecord(100.0, "base_link", "laser", Pose2D(0.2, 0, 0), static=True)]
    for t, _, odom, scan in drive(WIDE)[:20]:
        records += [OdomRecord(t, odom), TransformRecord(t, "odom", "base_link", odom),
                    ScanRecord(t, scan)]
    write_bag(tmp_path / "raw.bag", records, "ros1")
    save_map(room_map(), tmp_path / "map.yaml")
    before = snapshot(tmp_path / "raw.bag", tmp_path / "map.yaml")
    assert inject(tmp_path / "case", tmp_path / "map.yaml", tmp_path / "raw.bag",
                  "--seed", 1) == 2
    one_line_error(capsys, "recorded laser pose")
    assert not (tmp_path / "case").exists() and snapshot(*before) == before


def test_scoring_a_map_of_another_grid_is_refused(case, tmp_path, capsys):
    stale = load_map(case / "stale.yaml")
    save_map(OccupancyGrid(stale.data[:-3], stale.resolution, stale.origin),
             tmp_path / "small.yaml")
    save_map(OccupancyGrid(stale.data, stale.resolution, (0.0, 0.0)), tmp_path / "moved.yaml")
    before = snapshot(*(case / f for f in case_folder.CASE_FILES))
    for name in ("small", "moved"):
        assert main(["score", str(case), str(tmp_path / f"{name}.yaml"), "--json",
                     str(tmp_path / "s.json")]) == 2
        one_line_error(capsys, "not on the case's grid")
    assert not (tmp_path / "s.json").exists() and snapshot(*before) == before
    assert main(["score", str(tmp_path), str(case / "stale.yaml")]) == 2
    one_line_error(capsys, "not a case folder")


# --- a real building ---------------------------------------------------------------------------

@pytest.mark.skipif(not (RADISH / "aces.log.gz").exists(),
                    reason=f"the aces log is not at {RADISH} (the public Radish data)")
def test_aces_takes_four_removed_and_four_added_boxes_and_updates(tmp_path, capsys):
    from onboard.logmap import map_from_log

    log = RADISH / "aces.log.gz"
    map_from_log(log, tmp_path / "aces.yaml", progress=False)
    assert inject(tmp_path / "case", tmp_path / "aces.yaml", log, "--seed", 1) == 0
    record = yaml.safe_load((tmp_path / "case" / "case.yaml").read_text())
    assert record["placed"] == {"removed": 4, "added": 4, "moved": 0, "people": 0}
    assert all(b["views"] >= 5 for b in record["boxes"]) and record["scans"] == 440
    capsys.readouterr()
    assert main(["update", "--map", str(tmp_path / "case" / "stale.yaml"), "--log",
                 str(tmp_path / "case" / "log.clf"), "--out", str(tmp_path / "up.yaml"),
                 "--poses", "recorded", "--no-progress"]) == 0
    assert "440 scans read, 440 used" in capsys.readouterr().out
    s = case_folder.score_case(tmp_path / "case", load_map(tmp_path / "up.yaml"))
    assert s["removed_freed"] > 0.5
