"""The updater as it runs (one fused kernel call per scan, with the shortcuts of
docs/algorithm.md) against the steps written plainly, one after the other, in naive_updater.py:
the flags of a scan, and scan after scan the buffers, the flag counts, the decided cells, the
hit buffers' drawn cells and the output map, bit for bit, in a synthetic room with the
paper's rules and with this project's (the seen-surface guard, fill_gaps, the growth into the
unknown, the unanimous rule, the gate's held-back scans that confirm surfaces ...)."""

from __future__ import annotations

import numpy as np
import pytest

import naive_updater as naive
import synthetic_room as world
from gridmap import FREE, UNKNOWN, OccupancyGrid
from updater import MapUpdater, ScanStatus, UpdaterConfig
from updater.gating import CONFIRMING

BOX = world.Rect(4.0, 4.0, 5.0, 4.6)           # in M, hollow; gone from the world
MOVED = world.Rect(5.2, 6.4, 6.2, 7.0)         # a box the world has and M has not
NEW = world.Rect(2.0, 8.0, 2.6, 8.6)
POST = world.Circle(8.0, 3.0, 0.4)             # in both


def session(seed: int, scans: int, beams: int = 360, unknown_corner: bool = False,
            random_ranges: float = 0.0):
    """M (the room with BOX, hollow, and POST), and scans of the world (BOX gone, MOVED and NEW
    there) from a robot circling with 2 cm / 1 deg pose noise, 3 % of the beams lost and a
    share ``random_ranges`` of them at a random range: (M, [(scan, noisy sensor pose, true
    pose as odometry)])."""
    ref = world.rasterise(world.room_walls() + [POST], hollow=[BOX])
    if unknown_corner:          # space for the map to grow into
        data = ref.data.copy()
        h, w = data.shape
        data[h // 2:, w // 2:] = UNKNOWN
        ref = OccupancyGrid(data, ref.resolution, ref.origin)
    shapes = world.room_walls() + [MOVED, NEW, POST]
    rng = np.random.default_rng(seed)
    drive = world.Drive(seconds=scans / 10.0, seed=seed, radius=rng.uniform(2.0, 3.5))
    out = []
    for true, noisy, t in drive.steps():
        scan = world.full_scan(shapes, true, t, beams=beams)
        pick = rng.random(scan.beams)
        scan.ranges[pick < random_ranges] = rng.uniform(0.1, 8.0, (pick < random_ranges).sum())
        scan.ranges[pick > 0.97] = np.nan
        out.append((scan, noisy, true))
    return ref, out


def bits(packed: np.ndarray, shape) -> np.ndarray:
    return np.unpackbits(packed, bitorder="little")[:shape[0] * shape[1]].reshape(shape) == 1


ROBOT = UpdaterConfig.profile("robot")
CONFIGS = {
    "paper, every scan": (UpdaterConfig(gating=False), False),
    "paper, gated": (UpdaterConfig.profile("paper"), False),
    "paper's rules, fill_gaps, skipped beams walk, 2 virtual beams a beam, removed skip "
    "across": (UpdaterConfig(gating=False, fill_gaps=True, walk_skipped_beams=True,
                             virtual_to_measured_ratio=2, removed_skip_across=True), False),
    "robot": (ROBOT, True),
    "robot, every scan, fill_gaps": (UpdaterConfig.profile("robot", {
        "gating": False, "fill_gaps": True, "spread_removed": False,
        "free_with_neighbours": False}), True),
    "counts of their own (N_b 16), growing, exact-state support": (UpdaterConfig(
        gating=False, buffer_size=16, threshold=9, unanimous_min=3, grow_into_unknown=True,
        support_exact_state=True), True),
}


@pytest.mark.parametrize("name", list(CONFIGS))
def test_the_fused_scan_keeps_the_buffers_of_the_steps_one_after_the_other(name):
    cfg, corner = CONFIGS[name]
    ref, scans = session(seed=len(name) % 7, scans=60, unknown_corner=corner)
    fused, plain = MapUpdater(ref, cfg), naive.NaiveUpdater(ref, cfg)
    mask, shape = np.uint16((1 << cfg.buffer_size) - 1), ref.shape
    free = ref.data.reshape(-1) == FREE
    seen = {status: 0 for status in ("processed", "lost", "confirmed")}
    for scan, pose, odometry in scans:
        report = fused.process(scan, pose, odometry)
        if report.status in (ScanStatus.PROCESSED, ScanStatus.LOST):
            assert plain.process(scan, pose) == (report.status is ScanStatus.PROCESSED)
            seen["lost" if report.dropped_as_lost else "processed"] += 1
        elif report.reason in CONFIRMING and cfg.gate_confirm:
            plain.confirm(scan, pose)
            seen["confirmed"] += 1
        assert np.array_equal(fused._hist.reshape(-1) & mask, plain.hist)
        assert np.array_equal(bits(fused._decided, shape), plain.decided())
        if cfg.grow_into_unknown:
            assert np.array_equal(fused._hits.dense().reshape(-1), plain.hits)
            assert np.array_equal(bits(fused._drawn, shape), plain.drawn())
        # the counts, where a rule reads them: up to T on free cells (a settled one stops
        # counting there), up to N_b on the others (one full of changes stops there)
        counts = fused._flag_counts()
        if counts is not None:
            for bound, cells in ((cfg.threshold, free), (cfg.buffer_size, ~free)):
                assert np.array_equal(np.minimum(counts, bound)[cells],
                                      np.minimum(plain.counts, bound)[cells])
    assert seen["processed"] >= 5 and fused.n_changed > 0
    assert seen["confirmed"] > 5 or not (cfg.gating and cfg.gate_confirm)
    if not (cfg.spread_removed or cfg.free_with_neighbours):
        assert np.array_equal(fused.updated_map().data, plain.updated_map())


SCENES = [(seed, cfg, corner) for seed in range(4) for cfg, corner in (
    (UpdaterConfig(gating=False), False),
    (UpdaterConfig(gating=False, fill_gaps=True, walk_skipped_beams=True), False),
    (UpdaterConfig(gating=False, grow_into_unknown=True, removed_skip_across=True), True),
    (UpdaterConfig(gating=False, grow_into_unknown=True, virtual_to_measured_ratio=3,
                   seen_surface_radius=0.12), True))]


@pytest.mark.parametrize("seed, cfg, corner", SCENES)
def test_the_flags_of_one_scan_are_those_of_the_steps(seed, cfg, corner):
    """The changed and unchanged flags of a scan as ``flag_scan`` lists them, with no cell
    taken as settled beforehand (the free walks then flag every free cell they cross),
    against the steps' sets: the guard, the walks' kinds, fill_gaps, the hits that confirm
    M's surfaces and the unknown cells hit all leave their mark on the flags."""
    ref, scans = session(seed, scans=seed * 7 + 5, beams=720, unknown_corner=corner,
                         random_ranges=0.1 if seed == 3 else 0.0)
    scan, pose, _ = scans[-1]
    fused, plain = MapUpdater(ref, cfg), naive.NaiveUpdater(ref, cfg)
    fused._un_marks[:] = 0
    report = fused.process(scan, pose)
    assert report.status is ScanStatus.PROCESSED
    beams = plain.classify(scan, pose)
    changed, unchanged, hit = naive.scan_flags(ref.data, plain.enclosed, beams, cfg,
                                               ref.resolution)
    ws = fused._ws
    assert set(ws.changed[:report.changed_flags].tolist()) == changed
    assert set(ws.unchanged[:report.unchanged_flags].tolist()) == unchanged
    assert report.changed_flags == len(changed) > 20 and len(unchanged) > 300
    assert beams.changes > 0 and (len(hit) > 10 or not cfg.grow_into_unknown)


def test_the_guard_and_the_unknown_hits_keep_flags_off_their_cells():
    """The plain steps themselves: without the seen-surface guard more cells get changed
    flags, and so on, so the comparisons above see the rules at work."""
    ref, scans = session(1, scans=12, beams=720, unknown_corner=True)
    scan, pose, _ = scans[-1]
    cfg = UpdaterConfig(gating=False, grow_into_unknown=True)
    plain = naive.NaiveUpdater(ref, cfg)
    beams = plain.classify(scan, pose)
    guarded = naive.scan_flags(ref.data, plain.enclosed, beams, cfg, ref.resolution)[0]
    bare = naive.scan_flags(ref.data, plain.enclosed, beams,
                            UpdaterConfig(gating=False, grow_into_unknown=True,
                                          seen_surface_radius=0.0), ref.resolution)[0]
    assert guarded < bare
