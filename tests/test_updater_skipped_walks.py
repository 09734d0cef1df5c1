"""``UpdaterConfig.walk_skipped_beams``: the beams skipped beside a kept change also walk for
removed obstacles. A beam through the side of a removed box pairs, within the classifier's
window, with the point just past the box, so the paper's rules give that side no flag from
it; with the key, its walk flags the box cells it crosses. Exact poses here: with pose noise
the same walks wear the edges of real walls (benchmarks/RESULTS.md), which is why the key is
off in every default."""

from __future__ import annotations

import numpy as np

from gridmap import FREE, OCCUPIED, Pose2D
from updater import MapUpdater, UpdaterConfig

import synthetic_room as world

BOX = world.Rect(6.4125, 7.1125, 7.0125, 7.9125)       # 0.6 x 0.8 m, removed from the world


def drive_past(config: UpdaterConfig):
    """A robot drives along y = 1 m, some 6 m from a box that M has and the world has not,
    keeping a scan a metre (a sparse recording), 360 beams, every scan processed."""
    walls = world.room_walls()
    ref = world.rasterise(walls + [BOX])
    updater = MapUpdater(ref, config)
    for k, x in enumerate(np.arange(1.5, 9.6, 1.0)):
        pose = Pose2D(float(x), 1.0, 0.0)
        updater.process(world.full_scan(walls, pose, float(k), beams=360), pose)
    return ref, updater.updated_map()


def test_skipped_beams_free_the_sides_of_a_removed_box_and_no_wall():
    base = UpdaterConfig(gating=False, unanimous_min=3)
    ref, plain = drive_past(base)
    _, walked = drive_past(UpdaterConfig(gating=False, unanimous_min=3,
                                         walk_skipped_beams=True))
    box = world.cells_of(BOX) & (ref.data == OCCUPIED)
    walls = (ref.data == OCCUPIED) & ~box
    freed_plain = box & (plain.data == FREE)
    freed_walked = box & (walked.data == FREE)
    # the walks add freed cells of the box and take none away
    assert np.all(freed_walked[freed_plain])
    assert freed_walked.sum() >= freed_plain.sum() + 10     # 184 and 206 of 221 when written
    # with exact poses no wall cell is freed either way
    assert not np.any(walls & (plain.data == FREE))
    assert not np.any(walls & (walked.data == FREE))
