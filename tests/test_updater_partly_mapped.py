"""A partly mapped place: beams that look into unknown space are changes only because the map
does not know what is there, and they say nothing about the pose; the lost check leaves them
out (docs/algorithm.md, "Lost check")."""

import numpy as np

from gridmap import UNKNOWN, Pose2D
from updater import MapUpdater, ScanStatus, UpdaterConfig

import synthetic_room as world

CONFIG = UpdaterConfig(gating=False)


def partly_mapped():
    """The room, but M knows only its left third: the rest is unknown."""
    walls = world.room_walls()
    grid = world.rasterise(walls)
    grid.data[:, int(4.0 / world.RES):] = UNKNOWN
    return walls, grid


def test_scans_that_look_into_the_unknown_are_not_dropped_as_lost():
    walls, ref = partly_mapped()
    pose = Pose2D(3.5, 5.5, 0.0)                   # in the known part, facing the unknown
    scan = world.partial_scan(walls, pose, 0.0, fov_deg=180.0, beams=361)
    report = MapUpdater(ref, CONFIG).process(scan, pose)
    assert report.raw_detected_changes > 0.8 * report.valid_beams    # lost by the old rule
    assert report.status is ScanStatus.PROCESSED


def test_a_wrong_pose_in_the_known_part_is_still_dropped_as_lost():
    walls, ref = partly_mapped()
    true = Pose2D(2.0, 5.5, 0.0)
    scan = world.full_scan(walls, true, 0.0)
    wrong = Pose2D(2.6, 5.0, 0.6)                  # 0.8 m and 34 degrees off
    report = MapUpdater(ref, CONFIG).process(scan, wrong)
    assert report.status is ScanStatus.LOST


def test_in_a_fully_known_room_the_rule_is_the_old_one():
    walls = world.room_walls()
    ref = world.rasterise(walls)
    pose = Pose2D(5.5, 5.5, 0.0)
    scan = world.full_scan(walls, pose, 0.0)
    wrong = Pose2D(6.3, 4.9, 0.7)
    ok, lost = MapUpdater(ref, CONFIG).process(scan, pose), \
        MapUpdater(ref, CONFIG).process(scan, wrong)
    assert ok.status is ScanStatus.PROCESSED and lost.status is ScanStatus.LOST
    # every valid beam's expected ray ends on a wall: the known beams are all the valid ones
    assert lost.raw_detected_changes > 0.8 * lost.valid_beams


def _drive_into_the_unknown(config):
    """Circle the room (its right two thirds unknown in M) with exact poses and odometry."""
    walls, ref = partly_mapped()
    updater = MapUpdater(ref, config)
    for true, _, t in world.Drive(seconds=60.0, pos_noise=0.0, yaw_noise=0.0).steps():
        updater.process(world.full_scan(walls, true, t), true, odometry=true)
    return walls, ref, updater


def test_the_map_grows_into_the_unknown_part_by_the_same_buffers():
    """Seen through, the unknown part becomes free; hit, its walls are drawn (T of N_b hits);
    with ``grow_into_unknown`` off it stays unknown apart from what detected changes free."""
    walls, ref, updater = _drive_into_the_unknown(UpdaterConfig(grow_into_unknown=True))
    out = updater.updated_map().data
    unknown = ref.data == UNKNOWN
    inside = world.cells_of(world.Rect(4.5, 1.0, 10.0, 10.0))
    whole = world.rasterise(walls).data
    # the walls' inner faces there: wall cells beside the room's free space
    walls_there = unknown & (whole == 100) & world.dilate(whole == 0, 1)
    assert (out[inside & unknown] == 0).mean() > 0.95                 # free
    drawn = (out == 100) & unknown
    assert (drawn & walls_there).sum() > 0.8 * walls_there.sum()
    assert not np.any(drawn & ~world.dilate(walls_there, 1))          # nothing else drawn
    assert len(updater.drawn_cells()[0]) == int(drawn.sum())
    _, _, plain = _drive_into_the_unknown(UpdaterConfig(grow_into_unknown=False))
    assert not np.any((plain.updated_map().data == 100) & unknown)


def test_hit_buffers_are_saved_and_loaded_with_the_state(tmp_path):
    _, _, updater = _drive_into_the_unknown(UpdaterConfig(grow_into_unknown=True))
    updater.save(tmp_path / "s.npz")
    loaded = MapUpdater.load(tmp_path / "s.npz")
    assert np.array_equal(loaded.updated_map().data, updater.updated_map().data)
    assert len(loaded.drawn_cells()[0]) == len(updater.drawn_cells()[0]) > 100


def _thin_faced_room():
    """M of the room with its right wall one cell thick and open unknown space behind it, and
    its upper right corner unknown (x 7-10.55 m, y 7-10.5 m)."""
    walls = world.room_walls()
    ref = world.rasterise(walls)
    ref.data[:, int(round(10.55 / world.RES)):] = UNKNOWN
    ref.data[int(7.0 / world.RES):int(round(10.5 / world.RES)),
             int(7.0 / world.RES):int(round(10.55 / world.RES))] = UNKNOWN
    return walls, ref


def _drive_shifted(config, shift=0.06):
    """Circle the room with every pose 6 cm too far right: hits on the right wall land a cell
    behind M's face of it."""
    walls, ref = _thin_faced_room()
    updater = MapUpdater(ref, config)
    for true, _, t in world.Drive(seconds=60.0, pos_noise=0.0, yaw_noise=0.0).steps():
        believed = Pose2D(true.x + shift, true.y, true.theta)
        updater.process(world.full_scan(walls, true, t), believed, odometry=believed)
    return ref.data, updater.updated_map().data


def test_hits_beside_a_surface_of_m_do_not_thicken_it():
    """``grow_clear_of_surfaces``: with the pose a cell off, the hits on a face of M land in
    the open unknown space behind it. Drawn, the face grows into the wall; with the rule, none
    of them is, while the unknown corner's walls still are."""
    config = UpdaterConfig(gating=False, grow_into_unknown=True)
    ref, plain = _drive_shifted(config)
    _, clear = _drive_shifted(UpdaterConfig(gating=False, grow_into_unknown=True,
                                            grow_clear_of_surfaces=True))
    occupied = ref == 100
    # the cells just behind the right wall's face of M, below the unknown corner
    behind = np.zeros_like(occupied)
    behind[int(1.0 / world.RES):int(6.5 / world.RES), int(round(10.55 / world.RES))] = True
    assert np.all(ref[behind] == UNKNOWN) and np.all(np.roll(occupied, 1, axis=1)[behind])
    assert ((plain == 100) & behind).sum() > 0.8 * behind.sum()          # thickened
    assert not np.any((clear == 100) & behind)                           # not with the rule
    # the walls of the unknown corner, two cells and more from M's surfaces, are drawn alike
    corner = (ref == UNKNOWN) & ~world.dilate(occupied, 1)
    corner[:int(7.0 / world.RES)] = False
    corner[:, :int(7.0 / world.RES)] = False
    assert ((plain == 100) & corner).sum() > 50
    assert ((clear == 100) & corner).sum() >= 0.9 * ((plain == 100) & corner).sum()


def test_the_far_face_of_a_thin_wall_is_still_drawn():
    """Only a cell behind a surface of M as the beam comes is left out: M knows a partition
    two cells thick by its left cell alone (everything right of it unknown), and the beams
    from the right that end on its right cell, beside M's cell but in front of it, draw it."""
    walls = world.room_walls() + [world.Rect(7.6, 4.0, 7.7, 6.0)]
    ref = world.rasterise(walls)
    ref.data[:, int(round(7.65 / world.RES)):] = UNKNOWN
    config = UpdaterConfig(gating=False, grow_into_unknown=True, grow_clear_of_surfaces=True)
    updater = MapUpdater(ref, config)
    for true, _, t in world.Drive(seconds=60.0, pos_noise=0.0, yaw_noise=0.0).steps():
        updater.process(world.full_scan(walls, true, t), true, odometry=true)
    out = updater.updated_map().data
    far_face = np.zeros_like(out, dtype=bool)
    far_face[int(4.0 / world.RES):int(6.0 / world.RES), int(round(7.65 / world.RES))] = True
    near_face = np.roll(far_face, -1, axis=1)
    assert np.all(ref.data[far_face] == UNKNOWN) and np.all(ref.data[near_face] == 100)
    assert (out[far_face] == 100).mean() > 0.8
