"""``UpdaterConfig.spread_removed``: a removed object is freed as a whole. An occupied cell of M
next to one the rule freed, every flag of which says changed (one at least), is freed too,
within a structure of M's occupied cells of at most ``spread_max_area`` that no scan still
sees (no cell of it with an unchanged flag among its recent ones). A sparse recording sees
the sides of a box through once or twice (fewer than the unanimous rule's 3), and people
walking past hide more of its views; the rule frees them with the rest of the box."""

from __future__ import annotations

import numpy as np
import pytest

from gridmap import FREE, OCCUPIED, UNKNOWN, Pose2D
from updater import MapUpdater, UpdaterConfig, UpdaterError
from updater import steps

import synthetic_room as world

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


def test_a_box_against_a_wall_gets_no_spread_and_the_wall_is_kept():
    """A box flat against a wall is one structure with it in M, larger than an object: the
    spread leaves it to the decision rule, so the output is the rule's alone."""
    box = world.Rect(4.0125, 9.9125, 4.8125, 10.5)        # 0.8 x 0.6 m, against the top wall
    wall = world.rasterise(world.room_walls()).data == OCCUPIED
    _, plain = drive_past(UpdaterConfig(**BASE), box=box, y=5.0)
    _, spread = drive_past(UpdaterConfig(**BASE, spread_removed=True), box=box, y=5.0)
    after = spread.updated_map().data
    np.testing.assert_array_equal(after, plain.updated_map().data)
    assert not np.any(wall & (after == FREE))


def test_the_same_box_apart_from_the_wall_is_spread():
    box = world.Rect(4.0125, 9.5125, 4.8125, 10.1125)     # 0.4 m clear of the top wall
    wall = world.rasterise(world.room_walls()).data == OCCUPIED
    ref, plain = drive_past(UpdaterConfig(**BASE), box=box, y=5.0)
    _, spread = drive_past(UpdaterConfig(**BASE, spread_removed=True), box=box, y=5.0)
    cells = world.cells_of(box) & (ref.data == OCCUPIED)
    before, after = plain.updated_map().data, spread.updated_map().data
    assert (cells & (after == FREE)).sum() >= (cells & (before == FREE)).sum() + 5  # 200, 221
    assert not np.any(wall & (after == FREE))


def test_spread_needs_the_flag_counts():
    with pytest.raises(UpdaterError, match="spread_removed.*unanimous_min"):
        UpdaterConfig(spread_removed=True)


# --- the kernel against a reference written apart ------------------------------------------
def components(occ, confirmed):
    """Per occupied cell, the size of its 8-connected component and whether a cell of it is
    confirmed (a plain flood fill)."""
    h, w = occ.shape
    sizes = np.zeros(occ.shape, int)
    seen = np.zeros(occ.shape, bool)
    label = np.full(occ.shape, -1)
    for r0 in range(h):
        for c0 in range(w):
            if not occ[r0, c0] or label[r0, c0] >= 0:
                continue
            todo, cells = [(r0, c0)], []
            label[r0, c0] = 1
            while todo:
                r, c = todo.pop()
                cells.append((r, c))
                for rr in range(max(r - 1, 0), min(r + 2, h)):
                    for cc in range(max(c - 1, 0), min(c + 2, w)):
                        if occ[rr, cc] and label[rr, cc] < 0:
                            label[rr, cc] = 1
                            todo.append((rr, cc))
            for r, c in cells:
                sizes[r, c] = len(cells)
                seen[r, c] = any(confirmed[q] for q in cells)
    return sizes, seen


def reference_spread(ref, flags, counts, decided, max_cells, window=10):
    """Repeat until nothing moves: an occupied cell, not decided, in an occupied component of
    at most ``max_cells`` cells none of which is confirmed (an unchanged flag among its last
    min(count, window)), with counts >= 1 and all its last flags changed, joins when an
    8-neighbour is a decided occupied cell or has joined."""
    h, w = ref.shape
    occ = ref == OCCUPIED
    confirmed = occ & (counts > 0) & (flags < np.minimum(counts, window))
    ok = occ & ~decided & (counts >= 1) & (flags == np.minimum(counts, window))
    sizes, seen_still = components(occ, confirmed)
    ok &= (sizes <= max_cells) & ~seen_still
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


def random_case(seed):
    rng = np.random.default_rng(seed)
    h, w = 24, 31
    ref = rng.choice(np.array([FREE, OCCUPIED, UNKNOWN], np.int8), (h, w), p=[0.6, 0.3, 0.1])
    counts = rng.integers(0, 14, (h, w))
    full = (1 << np.minimum(counts, 10)) - 1
    # nearly all cells with every recent flag changed, the rest any flags of those
    flags_bits = np.where(rng.random((h, w)) < 0.93, full, rng.integers(0, 1 << 10, (h, w))
                          & full)
    return ref, counts, flags_bits, rng.random((h, w)) < 0.06


def kernel_spread(seed, max_area):
    ref, counts, flags_bits, decided = random_case(seed)
    h, w = ref.shape
    cfg = UpdaterConfig(unanimous_min=3, spread_removed=True, spread_max_area=max_area)
    hist = ((counts << steps.count_shift(cfg)) | flags_bits).astype(np.uint16)
    bits = np.packbits(decided.reshape(-1), bitorder="little")
    got = steps.spread_freed(hist.reshape(-1), np.zeros(0, np.uint8), ref.reshape(-1), bits, w,
                             0.05, cfg)
    return np.unpackbits(got, bitorder="little")[:h * w].reshape(h, w).astype(bool)


@pytest.mark.parametrize("seed", [0, 1, 3])
@pytest.mark.parametrize("max_area", [0.05, 1.0])        # 20 and 400 cells at 5 cm
def test_spread_kernel_against_reference(seed, max_area):
    ref, counts, flags_bits, decided = random_case(seed)
    flags = np.bitwise_count(flags_bits.astype(np.uint16)).astype(int)
    want = reference_spread(ref, flags, counts, decided, round(max_area / 0.05**2))
    assert want.sum() > 0
    np.testing.assert_array_equal(kernel_spread(seed, max_area), want)


def test_large_structures_get_no_spread():
    # seed 0 has structures of 21-400 cells, none seen still, where the spread reaches (26
    # cells with a limit of 20, 110 with 400 when written)
    assert kernel_spread(0, 0.05).sum() < kernel_spread(0, 1.0).sum()
