"""``UpdaterConfig.spread_removed``: a removed object is freed as a whole. An occupied cell of M
next to one the rule freed, every flag of which says changed (one at least), is freed too,
unless it lies beside a surface the scans still see. A sparse recording sees the sides of a
box through once or twice (fewer than the unanimous rule's 3), and people walking past hide
more of its views; the rule frees them with the rest of the box."""

from __future__ import annotations

import numpy as np
import pytest

from gridmap import FREE, OCCUPIED, UNKNOWN, Pose2D
from updater import MapUpdater, UpdaterConfig, UpdaterError
from updater import steps

try:
    import synthetic_room as world
except ImportError:  # tests collected as a package
    from tests import synthetic_room as world

BOX = world.Rect(6.4125, 7.1125, 7.0125, 7.9125)       # 0.6 x 0.8 m, removed from the world
BASE = dict(gating=False, unanimous_min=3)


def drive_past(config: UpdaterConfig, box=BOX, y=1.0):
    """A robot drives along y, keeping a scan a metre (a sparse recording), 360 beams, every
    scan processed, past a box that M has and the world has not."""
    walls = world.room_walls()
    ref = world.rasterise(walls + [box])
    updater = MapUpdater(ref, config)
    for k, x in enumerate(np.arange(1.5, 9.6, 1.0)):
        pose = Pose2D(float(x), y, 0.0)
        updater.process(world.full_scan(walls, pose, float(k), beams=360), pose)
    return ref, updater


def test_the_sides_seen_once_or_twice_are_freed_with_the_box():
    ref, plain = drive_past(UpdaterConfig(**BASE))
    _, spread = drive_past(UpdaterConfig(**BASE, spread_removed=True))
    box = world.cells_of(BOX) & (ref.data == OCCUPIED)
    walls = (ref.data == OCCUPIED) & ~box
    before, after = plain.updated_map().data, spread.updated_map().data
    freed_before, freed_after = box & (before == FREE), box & (after == FREE)
    assert np.all(freed_after[freed_before])
    # the cells it adds are the box's cells seen through, fewer than 3 times, never hit
    added = freed_after & ~freed_before
    counts = spread._hist >> np.uint16(steps.count_shift(spread.config))
    flags = np.bitwise_count(spread._hist & np.uint16(steps.buffer_mask(spread.config)))
    assert added.sum() >= 10                              # 184 -> 217 of 221 when written
    assert np.all((counts[added] >= 1) & (counts[added] < 3) & (flags[added] == counts[added]))
    assert not np.any(walls & (after == FREE))
    # the rule's cells are the output's, not the decision rule's
    assert spread.n_changed == plain.n_changed
    # and they are not counted as evidence still pending
    assert spread.evidence_summary()["pending_cells"] == \
        plain.evidence_summary()["pending_cells"] - int(added.sum())


def test_a_box_against_a_wall_is_freed_and_the_wall_kept():
    """The wall behind the box is hit by the beams that passed through where the box was:
    its cells are confirmed, and the spread stops beside them."""
    box = world.Rect(4.0125, 9.9125, 4.8125, 10.5)        # 0.8 x 0.6 m, against the top wall
    wall = world.rasterise(world.room_walls()).data == OCCUPIED
    ref, plain = drive_past(UpdaterConfig(**BASE), box=box, y=5.0)
    _, spread = drive_past(UpdaterConfig(**BASE, spread_removed=True), box=box, y=5.0)
    box_cells = world.cells_of(box) & (ref.data == OCCUPIED) & ~wall
    before, after = plain.updated_map().data, spread.updated_map().data
    assert (box_cells & (after == FREE)).sum() >= \
        (box_cells & (before == FREE)).sum() + 10         # 132 -> 153 of 204 when written
    assert not np.any(wall & (after == FREE))
    assert not np.any(box_cells & world.dilate(wall, 1) & (after == FREE))


def test_spread_needs_the_flag_counts():
    with pytest.raises(UpdaterError, match="spread_removed.*unanimous_min"):
        UpdaterConfig(spread_removed=True)


# --- the kernel against a reference written apart ------------------------------------------
def reference_spread(ref, flags, counts, decided, window=10):
    """Repeat until nothing moves: an occupied cell, not decided, with counts >= 1, all its
    last min(count, window) flags changed and no confirmed 8-neighbour, joins when an
    8-neighbour is a decided occupied cell or has joined."""
    h, w = ref.shape
    occ = ref == OCCUPIED
    confirmed = occ & (counts > 0) & (flags < np.minimum(counts, window))
    ok = occ & ~decided & (counts >= 1) & (flags == np.minimum(counts, window))
    for r in range(h):
        for c in range(w):
            block = confirmed[max(r - 1, 0):r + 2, max(c - 1, 0):c + 2]
            if block.sum() - confirmed[r, c] > 0:
                ok[r, c] = False
    grown = decided & occ
    joined = np.zeros_like(ok)
    while True:
        moved = False
        for r in range(h):
            for c in range(w):
                if ok[r, c] and not joined[r, c] and \
                        grown[max(r - 1, 0):r + 2, max(c - 1, 0):c + 2].any():
                    joined[r, c] = grown[r, c] = moved = True
        if not moved:
            return joined


@pytest.mark.parametrize("seed", range(6))
def test_spread_kernel_against_reference(seed):
    rng = np.random.default_rng(seed)
    h, w = 24, 31
    cfg = UpdaterConfig(unanimous_min=3, spread_removed=True)
    shift, window = steps.count_shift(cfg), cfg.buffer_size
    ref = rng.choice(np.array([FREE, OCCUPIED, UNKNOWN], np.int8), (h, w), p=[0.3, 0.6, 0.1])
    counts = rng.integers(0, 14, (h, w))
    full = (1 << np.minimum(counts, window)) - 1
    # half the cells with every recent flag changed, the rest any flags of those
    flags_bits = np.where(rng.random((h, w)) < 0.6, full, rng.integers(0, 1 << window, (h, w))
                          & full)
    hist = ((counts << shift) | flags_bits).astype(np.uint16)
    decided = rng.random((h, w)) < 0.04
    bits = np.packbits(decided.reshape(-1), bitorder="little")
    got = steps.spread_freed(hist.reshape(-1), np.zeros(0, np.uint8), ref.reshape(-1), bits, w,
                             cfg)
    got = np.unpackbits(got, bitorder="little")[:h * w].reshape(h, w).astype(bool)
    flags = np.bitwise_count(flags_bits.astype(np.uint16)).astype(int)
    want = reference_spread(ref, flags, counts, decided, window)
    assert want.sum() > 5
    np.testing.assert_array_equal(got, want)
