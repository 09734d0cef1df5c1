"""The updater in synthetic rooms: a 10 x 10 m room mapped at 5 cm, scans ray-cast from the true
geometry, the robot circling at 0.5 m/s with 10 Hz scans, sensor poses with 2 cm / 1 deg noise
(seeded), smooth odometry for gating. Default configuration unless a test says otherwise."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gridmap import FREE, OCCUPIED, UNKNOWN, Pose2D
from gridmap.raycast import traverse
from updater import MapUpdater, UpdaterConfig

import synthetic_room as world

Circle, Drive, Rect = world.Circle, world.Drive, world.Rect

T = UpdaterConfig().threshold
# Box faces lie a quarter cell inside their edge cells, so every edge cell is mostly box.
BOX = Rect(4.9125, 5.1125, 6.1125, 5.9125)          # 1.2 x 0.8 m, inside the robot's circle


# The lidars: 360 deg at the robot's centre, and 270 deg (1081 beams) mounted off it.
LIDARS = {"360 centred": (None, world.full_scan),
          "270 off-centre": (Pose2D(0.25, 0.10, 0.20), world.partial_scan)}


def drive(ref, shapes, config=None, seconds=80.0, seed=0, each=None, offset=None,
          lidar="360 centred"):
    """Run the updater along the circle; ``shapes(t)`` or a fixed list is the world. The
    updater is told the sensor pose (noisy robot pose composed with the mount) and the true
    robot pose as odometry. Returns the updater and, per cell, how many processed scans hit
    it / saw it (true geometry)."""
    mount, make_scan = LIDARS[lidar]
    updater = MapUpdater(ref, config, profile="paper")
    hits = np.zeros(ref.shape, int)
    seen = np.zeros(ref.shape, int)
    for true, noisy, t in Drive(seconds=seconds, seed=seed).steps():
        sensor = true if mount is None else true.compose(mount)
        scan = make_scan(shapes(t) if callable(shapes) else shapes, sensor, t)
        pose = noisy if mount is None else noisy.compose(mount)
        pose = pose if offset is None else offset(pose)
        report = updater.process(scan, pose, odometry=true)
        if each is not None:
            each(updater, report)
        if report.processed and not report.dropped_as_lost:
            _count_views(ref, scan, sensor, hits, seen)
    return updater, hits, seen


def _count_views(ref, scan, pose, hits, seen):
    hx, hy = world.hit_points(scan, pose)
    rows, cols = ref.world_to_cell(hx, hy)
    np.add.at(hits, (rows, cols), 1)
    crossed = np.zeros(ref.shape, bool)
    for x, y in zip(hx, hy):
        d = math.hypot(x - pose.x, y - pose.y)
        if d > 0.3:      # crossed cells, short of the hit by the removed-obstacle skip
            f = (d - 0.2) / d
            r, c = traverse(ref, (pose.x, pose.y), (pose.x + f * (x - pose.x),
                                                    pose.y + f * (y - pose.y)))
            crossed[r, c] = True
    seen += crossed


def wall_watch(wall_mask):
    """A per-scan check that no cell of ``wall_mask`` is ever changed."""
    worst = [0]

    def each(updater, report):
        if report.processed:
            rows, cols = updater.changed_cells()
            worst[0] = max(worst[0], int(wall_mask[rows, cols].sum()))
    return each, worst


@pytest.mark.parametrize("lidar", list(LIDARS))
def test_removed_box_is_freed_and_no_wall_cell_ever_is(lidar):
    walls = world.room_walls()
    ref = world.rasterise(walls, hollow=[BOX])
    box = world.cells_of(BOX)
    each, worst = wall_watch((ref.data == OCCUPIED) & ~box)
    updater, hits, seen = drive(ref, walls, each=each, lidar=lidar)
    out = updater.updated_map().data
    outline = box & (ref.data == OCCUPIED) & (seen >= T)
    assert outline.sum() > 0.9 * (box & (ref.data == OCCUPIED)).sum()
    assert (out[outline] == FREE).mean() >= 0.99
    assert (out[box] == FREE).all()                 # the unknown interior was seen through
    assert worst[0] == 0
    rows, cols = updater.changed_cells()
    assert box[rows, cols].all()                    # nothing changed anywhere else
    assert updater.stats["processed"] > 60 and updater.stats["lost"] == 0


@pytest.mark.parametrize("lidar", list(LIDARS))
def test_added_box_appears_and_no_wall_cell_is_freed(lidar):
    walls = world.room_walls()
    ref = world.rasterise(walls)
    box = world.cells_of(BOX)
    each, worst = wall_watch(ref.data == OCCUPIED)
    # N_skip counts beams: the default 2 is 1 deg at the 360 lidar's 0.5 deg steps. The 270 deg
    # lidar has 0.25 deg steps, where the same angle is 4 beams (with 2, 1 deg of yaw noise
    # leaves 92-97 % of the facing cells occupied, depending on the seed).
    config = None if lidar == "360 centred" else UpdaterConfig(n_skip=4)
    updater, hits, seen = drive(ref, walls + [BOX], config, each=each, lidar=lidar)
    out = updater.updated_map().data
    facing = box & (hits >= T)          # cells that held a true hit in at least T scans
    assert facing.sum() >= 60
    assert (out[facing] == OCCUPIED).mean() >= 0.95
    assert worst[0] == 0
    # New cells hug the box: within one cell of it (noisy hits land just in front of a face).
    new = (ref.data == FREE) & (out == OCCUPIED)
    near = np.zeros_like(box)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            near |= np.roll(np.roll(box, dr, 0), dc, 1)
    assert new[~near].sum() == 0


def walker(speed):
    a, b = np.array([1.5, 2.0]), np.array([9.5, 9.0])
    length = float(np.linalg.norm(b - a))

    def at(t):
        s = (speed * t) % (2 * length)
        q = a + (b - a) * (s if s < length else 2 * length - s) / length
        return world.room_walls() + [Circle(float(q[0]), float(q[1]), 0.2)]
    return at


def test_walking_person_leaves_no_occupied_cell_with_default_gating():
    ref = world.rasterise(world.room_walls())
    worst = [0]

    def each(updater, report):
        worst[0] = max(worst[0], report.changed_cells)
    for speed in (1.0, 0.3):
        updater, _, _ = drive(ref, walker(speed), each=each)
        assert ((ref.data == FREE) & (updater.updated_map().data == OCCUPIED)).sum() == 0
        assert worst[0] == 0
    # Without gating, a slow walker does make cells change for a while: gating is what helps.
    updater, _, _ = drive(ref, walker(0.3), UpdaterConfig(gating=False), seconds=40, each=each)
    assert worst[0] > 0


def test_scans_off_by_half_a_metre_and_ten_degrees_are_dropped_and_change_nothing():
    walls = world.room_walls()
    shapes = walls + [BOX]
    ref = world.rasterise(walls, hollow=[BOX])
    # The default lost_fraction (0.8) catches gross errors only: in this room 0.5 m / 10 deg off
    # leaves 52-95 % of the valid beams as detected changes. 0.45 drops all of those scans
    # while correctly localised scans here stay below 5 %.
    config = UpdaterConfig(lost_fraction=0.45)
    for k, (angle, turn) in enumerate([(0, 10), (90, -10), (200, 10), (300, -10)]):
        a = math.radians(angle)

        def off(p, a=a, turn=turn):
            return Pose2D(p.x + 0.5 * math.cos(a), p.y + 0.5 * math.sin(a),
                          p.theta + math.radians(turn))
        fractions = []

        def each(updater, report):
            if report.processed:
                fractions.append(report.raw_detected_changes / report.valid_beams)
                assert report.dropped_as_lost and report.changed_flags == 0
        updater, _, _ = drive(ref, shapes, config, seconds=40, seed=k, each=each, offset=off)
        assert len(fractions) > 100            # a lost scan does not advance the gate
        assert not updater.change_counts().any() and updater.n_changed == 0
        assert (updater.updated_map().data == ref.data).all()
    fractions = []
    drive(ref, shapes, config, seconds=40, each=lambda u, r: fractions.append(
        r.raw_detected_changes / r.valid_beams) if r.processed else None)
    assert max(fractions) < 0.05


def test_default_lost_check_drops_gross_errors_and_they_change_nothing():
    walls = world.room_walls()
    ref = world.rasterise(walls, hollow=[BOX])
    dropped = []

    def each(updater, report):
        if report.dropped_as_lost:
            dropped.append(report.raw_detected_changes / report.valid_beams)
    updater, _, _ = drive(ref, walls + [BOX], seconds=30, each=each,
                          offset=lambda p: Pose2D(p.x + 1.0, p.y - 0.5, p.theta + 0.6))
    assert len(dropped) > 30 and min(dropped) > 0.8
    assert updater.stats["processed"] == updater.stats["lost"] == len(dropped)
    assert not updater.change_counts().any()


def test_last_check_closes_a_cut_object_against_its_unknown_interior():
    # M has a 2 x 1 m block (outline occupied, interior unknown); its western half is gone.
    walls = world.room_walls()
    block = Rect(4.5125, 5.0125, 6.5125, 6.0125)
    kept = Rect(5.5125, 5.0125, 6.5125, 6.0125)
    ref = world.rasterise(walls, hollow=[block])
    interior = world.cells_of(block) & (ref.data == UNKNOWN)
    results = {}
    for last_check in (True, False):
        # without the last check the interior is no longer enclosed, and the growth into the
        # unknown would close the cut from the kept half's hits: off here, to see the check
        updater, _, _ = drive(ref, walls + [kept], UpdaterConfig(
            last_check=last_check, grow_into_unknown=last_check))
        out = updater.updated_map().data
        assert updater.enclosed_unknown()[interior].all() == last_check
        # an unknown cell of the interior that touches a free cell is a hole in the outline
        free = np.pad(out == FREE, 1)
        touches = np.zeros_like(interior)
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                touches |= free[1 + dr:1 + dr + out.shape[0], 1 + dc:1 + dc + out.shape[1]]
        results[last_check] = (interior & (out == UNKNOWN) & touches).sum(), out
    holes, out = results[True]
    assert holes == 0 and results[False][0] > 5
    west = world.cells_of(Rect(4.5125, 5.0125, 5.3, 6.0125))
    assert (out[west] == FREE).all()                # the removed half is free
    closed = interior & (out == OCCUPIED) & (results[False][1] == UNKNOWN)
    assert closed.sum() >= 15                       # a new edge across the 1 m cut


def test_last_check_draws_no_wall_along_unknown_that_reaches_the_map_border():
    # A door in the east wall, closed in M, open in the world; beyond it unknown space that
    # reaches the map border, with a wall 0.3 m out. Seeing through the door must not close.
    walls = world.room_walls()
    east = Rect(10.5, 4.5125, 10.65, 6.5125)
    world_walls = [w for w in walls if w.x0 != 10.5] + [
        Rect(10.5, 0.35, 10.65, 4.5125), Rect(10.5, 6.5125, 10.65, 10.65),
        Rect(10.9, 0.35, 10.95, 10.65)]
    ref = world.rasterise(walls)
    updater, _, _ = drive(ref, world_walls, UpdaterConfig(grow_into_unknown=True))
    out = updater.updated_map().data
    door = world.cells_of(east) & (ref.data == OCCUPIED)
    assert (out[door] == FREE).mean() > 0.5         # the door is seen open
    assert not updater.enclosed_unknown().any()
    # no wall along the unknown beyond the door; the wall 0.3 m out, which the scans through
    # the door hit, is drawn (the growth into the unknown), and nothing else there: within two
    # cells of it, as the drive's 1 deg of pose noise scatters hits 5 m out by 9 cm
    far = world.dilate(world.cells_of(world_walls[-1]), 2)
    drawn = (ref.data == UNKNOWN) & (out == OCCUPIED)
    assert drawn.sum() > 50 and not np.any(drawn & ~far)


def _fragmented_outline(box_cells: np.ndarray, keep: int = 3, gap: int = 6) -> np.ndarray:
    """The outline cells of a box cut into pieces: ``keep`` cells kept, then ``gap`` left out,
    along each row and column of the outline."""
    inner = box_cells.copy()
    inner[1:-1, 1:-1] &= (box_cells[:-2, 1:-1] & box_cells[2:, 1:-1] & box_cells[1:-1, :-2]
                          & box_cells[1:-1, 2:])
    outline = box_cells & ~inner
    rows, cols = np.nonzero(outline)
    kept = np.zeros_like(outline)
    period = keep + gap
    along = np.where(np.isin(rows, [rows.min(), rows.max()]), cols, rows)
    kept[rows, cols] = (along % period) < keep
    return kept


def test_fill_gaps_completes_a_partly_mapped_face_and_leaves_the_rest_alone():
    """M holds only pieces of a box's outline (what an earlier session left), its interior
    free; the box is all there. Between the pieces a hit pairs with a piece within D(r), so
    the method as written never fills the gaps; ``fill_gaps`` flags hits with nothing of M in
    the 3 x 3 cells around them, and the facing gaps fill. Nothing else is added, no wall
    cell is freed."""
    walls = world.room_walls()
    box = world.cells_of(BOX)
    ref = world.rasterise(walls)
    pieces = _fragmented_outline(box)
    ref = ref.with_data(np.where(pieces, OCCUPIED, ref.data).astype(np.int8))
    near_pieces = world.dilate(pieces, 1)
    results = {}
    for fill in (False, True):
        each, worst = wall_watch(ref.data == OCCUPIED)
        updater, hits, _ = drive(ref, walls + [BOX], UpdaterConfig(fill_gaps=fill), each=each)
        out = updater.updated_map().data
        gaps = box & (hits >= T) & ~near_pieces        # facing cells two or more from a piece
        new = (ref.data == FREE) & (out == OCCUPIED)
        results[fill] = (float((world.dilate(out == OCCUPIED, 1) & gaps).sum() / gaps.sum()),
                         int(new[~world.dilate(box, 1)].sum()), worst[0], int(gaps.sum()))
    assert results[True][3] >= 25
    assert results[False][0] < 0.1 and results[True][0] >= 0.7     # measured: 0 and 0.79
    assert results[True][1] == 0 and results[True][2] == 0


def test_fill_gaps_draws_a_face_that_m_has_three_cells_behind():
    """M has the box 0.15 m further east than it stands: the world's west face pairs with M's
    within D(r), so the method as written never draws it; ``fill_gaps`` draws most of it (at
    0.1 m it does not: the rays grazing the face cross the free part of its cells)."""
    walls = world.room_walls()
    box = Rect(4.925, BOX.y0, 6.125, BOX.y1)         # the west face halfway through a cell
    ref = world.rasterise(walls, hollow=[Rect(box.x0 + 0.15, box.y0, box.x1 + 0.15, box.y1)])
    truth = world.rasterise(walls, hollow=[box])
    west = (truth.data == OCCUPIED) & world.cells_of(Rect(box.x0, box.y0 + 0.1, box.x0 + 0.01,
                                                          box.y1 - 0.1))
    assert west.sum() == 13 and not (west & world.dilate(ref.data == OCCUPIED, 1)).any()
    drawn = {}
    for fill in (False, True):
        updater, _, _ = drive(ref, walls + [box], UpdaterConfig(fill_gaps=fill))
        out = updater.updated_map().data
        drawn[fill] = int((west & world.dilate(out == OCCUPIED, 1)).sum())
        new = (ref.data == FREE) & (out == OCCUPIED)
        assert new[~world.dilate(world.cells_of(box), 1)].sum() == 0
    assert drawn[False] == 0 and drawn[True] >= 10                  # measured: 0 and 11


def test_fill_gaps_draws_nothing_beside_walls_from_noisy_poses():
    """A room that did not change, poses with 2 cm and 1 deg of noise: with ``fill_gaps`` no
    cell more than one cell from a wall becomes occupied and no wall cell is freed. What keeps
    it so is ``fill_gaps_free_margin``: without it the free cells two cells in front of a face,
    where noisy hits sometimes land, get no unchanged flags from the beams that pass them at
    long range, and a few are drawn."""
    walls = world.room_walls()
    ref = world.rasterise(walls + [BOX])
    beside = ~world.dilate(ref.data == OCCUPIED, 1)
    each, worst = wall_watch(ref.data == OCCUPIED)
    for seed in (0, 1):
        updater, _, _ = drive(ref, walls + [BOX], UpdaterConfig(fill_gaps=True), each=each,
                              seed=seed, lidar="270 off-centre")
        out = updater.updated_map().data
        assert ((out == OCCUPIED) & beside).sum() == 0
    assert worst[0] == 0
    updater, _, _ = drive(ref, walls + [BOX], UpdaterConfig(fill_gaps=True,
                                                            fill_gaps_free_margin=0.0),
                          seed=0, lidar="270 off-centre")
    assert ((updater.updated_map().data == OCCUPIED) & beside).sum() > 0     # measured: 4


def test_a_sub_cell_pose_error_leaves_kept_objects_whole_and_still_frees_a_removed_one():
    # Three kept boxes around the removed one: rays through the removed box's place graze
    # their corners. 4 cm of persistent error (under a cell) moves those rays into the kept
    # boxes' outline cells; the hits on the kept boxes in the same scans say they are there.
    kept = [Rect(6.3125, 5.1125, 6.9125, 5.5125), Rect(4.3125, 6.0125, 4.8125, 6.6125),
            Rect(5.3125, 4.3125, 5.9125, 4.9125)]
    walls = world.room_walls()
    ref = world.rasterise(walls + kept, hollow=[BOX])
    box = world.cells_of(BOX)
    kept_cells = np.zeros(ref.shape, bool)
    for k in kept:
        kept_cells |= world.cells_of(k)
    kept_cells &= ref.data == OCCUPIED
    # The seen-surface guard (radius) and the hits that confirm M's surfaces (confirm), each
    # alone and together (the default).
    radius = UpdaterConfig().seen_surface_radius
    freed = {}
    for guard in ((0.0, False), (radius, False), (0.0, True), (radius, True)):
        freed[guard] = 0
        for dx, dy in ((0.04, 0.0), (0.0, -0.04)):
            config = UpdaterConfig(seen_surface_radius=guard[0], confirm_hit_surfaces=guard[1])
            updater, _, seen = drive(ref, walls + kept, config,
                                     offset=lambda p: Pose2D(p.x + dx, p.y + dy, p.theta))
            out = updater.updated_map().data
            outline = box & (ref.data == OCCUPIED) & (seen >= T)
            assert (out[outline] == FREE).all() and (out[box] == FREE).all()
            assert not (out[(ref.data == OCCUPIED) & ~box & ~kept_cells] == FREE).any()
            freed[guard] += int((out[kept_cells] == FREE).sum())
    assert freed[0.0, False] > 40          # neither: corners of kept boxes freed (measured 58)
    assert freed[radius, False] <= 6       # the guard (measured 4)
    assert freed[0.0, True] <= 20          # the confirming hits (measured 16)
    assert freed[radius, True] == 0        # both


def test_cells_the_scans_hit_are_kept_where_m_knows_nothing_around_them():
    """M has the room's walls and three panels, and none of its free space: no virtual beam
    gets past the unknown cells around the sensor, so every beam is a detected change and only
    the hits can tell that M is right. With ``confirm_hit_surfaces`` a hit on a cell M has as
    occupied or unknown gives M's occupied cells there an unchanged flag: the walls and the
    panel that stays are kept, the panel gone for the first half of the drive and back for the
    second is kept, and the panel gone all along is still freed. With the paper's rules the
    walks of the beams that pass the walls' and panels' edges, and the unknown cells around
    them seen through (neighbour support), free parts of them (the Killian Court log's
    specks)."""
    walls = world.room_walls()
    back = Rect(5.1125, 5.4125, 5.9125, 5.5125)
    gone = Rect(4.1125, 6.6125, 4.9125, 6.7125)
    stays = Rect(6.1125, 4.3125, 6.9125, 4.4125)
    ref = world.rasterise(walls + [back, gone, stays])
    ref.data[ref.data == FREE] = UNKNOWN
    cells = {name: world.cells_of(r) & (ref.data == OCCUPIED)
             for name, r in (("back", back), ("gone", gone), ("stays", stays))}
    wall_cells = (ref.data == OCCUPIED) & ~cells["back"] & ~cells["gone"] & ~cells["stays"]
    freed = {}
    for confirm in (False, True):
        updater, _, _ = drive(ref, lambda t: walls + [stays] + ([back] if t >= 40.0 else []),
                              UpdaterConfig(confirm_hit_surfaces=confirm))
        out = updater.updated_map().data
        freed[confirm] = {name: int((out[c] == FREE).sum()) for name, c in cells.items()}
        freed[confirm]["walls"] = int((out[wall_cells] == FREE).sum())
        assert freed[confirm]["gone"] == cells["gone"].sum()
    assert freed[True]["walls"] == 0 and freed[True]["stays"] == 0
    assert freed[True]["back"] <= 0.1 * cells["back"].sum()          # measured 2 of 51
    assert freed[False]["walls"] > 50 and freed[False]["stays"] > 10  # measured 160 and 31
    assert freed[False]["back"] == cells["back"].sum()
