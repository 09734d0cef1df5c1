"""The updater's state stays small: the flag counts of the unanimous rule ride in the spare
bits of the flag buffers when there are enough of them.

The state of a 2000 x 2000 map is summed from the arrays the updater holds (their ``nbytes``,
the per-beam workspace included) after it processed real scans; the counts packed above the
flags are checked against a plain count of random flag sequences, past saturation; and a
state file of the layout before (format 1: the flags alone in the buffers, a ``seen`` array of
counts up to 255), written by the code before the packed counts
(``tests/data/golden/updater_state_format1.npz``), loads and continues as that code did, the
reports and maps it gave recorded in ``tests/data/golden`` (README.md there).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from gridmap import UNKNOWN, OccupancyGrid
from tests.data.golden import golden
from updater import MapUpdater, UpdaterConfig, UpdaterError, steps
from updater import _kernels as K
from updater.hit_tiles import HitTiles

from test_updater_speedup import room_session, same_config, unknown_corner

BAR_BYTES = 16e6
# mapupdate update's defaults without the rules that came after the code before the packed
# counts, which it cannot run: the run filter by width, the spread of freed objects, the
# neighbour support by M's value, the removed-obstacle walks' skip across a run, the freeing
# with free neighbours and the gate's single confirmation. The golden files of these tests
# were recorded with it.
ROBOT_AS_BEFORE = {**UpdaterConfig.profile("robot").to_dict(),
                   "min_run_width": 0.0, "spread_removed": False, "support_exact_state": False,
                   "removed_skip_across": False, "free_with_neighbours": False,
                   "gate_confirm_once": False}
STATE_FORMAT_1 = golden.HERE / "updater_state_format1.npz"
FLAG_KEYS = ("unchanged_flags", "changed_flags", "new_obstacle_flags")
SIZE = 2000


def embedded(ref: OccupancyGrid, size: int) -> OccupancyGrid:
    """``ref`` in the middle of a size x size map of unknown cells, at the same place."""
    data = np.full((size, size), UNKNOWN, np.int8)
    k = (size - ref.data.shape[0]) // 2
    data[k:k + ref.data.shape[0], k:k + ref.data.shape[1]] = ref.data
    origin = (ref.origin[0] - k * ref.resolution, ref.origin[1] - k * ref.resolution)
    return OccupancyGrid(data, ref.resolution, origin)


@pytest.fixture(scope="module")
def session():
    return room_session(3.0, 5)


def state_after_scans(config: UpdaterConfig, session, workspace: bool = True) -> int:
    """The updater's bytes after the session's scans (``workspace``: with the per-scan
    workspace, whose lists grow with the flags of the busiest scan)."""
    ref, scans, _ = session
    updater = MapUpdater(embedded(ref, SIZE), config)
    for scan, noisy, true in scans:
        updater.process(scan, noisy, odometry=true)
    assert updater.stats["processed"] > 0
    return updater.state_bytes() - (0 if workspace else updater._ws.nbytes())


def test_a_2000_map_with_the_unanimous_rule_stays_within_16_mb(session):
    # the decision rules of mapupdate update: the unanimous rule counts each cell's flags
    rules = UpdaterConfig(gating=False, unanimous_min=UpdaterConfig.profile("robot").unanimous_min)
    assert steps.count_shift(rules) == rules.buffer_size
    assert state_after_scans(rules, session) <= BAR_BYTES


def test_the_flag_counts_take_no_bytes_with_the_robots_defaults(session):
    """With the growth into the unknown, its hit buffers (two bytes a cell) come on top: the
    counts add nothing to them. (The workspace aside: uncounted, a free cell's buffer is
    settled sooner, so fewer flags are made and listed.)"""
    robot = UpdaterConfig.profile("robot")
    uncounted = UpdaterConfig.profile("robot", {"unanimous_min": 0,
                                 "spread_removed": False})
    assert state_after_scans(robot, session, False) == \
        state_after_scans(uncounted, session, False)


def test_a_2000_map_with_the_update_defaults_stays_within_16_mb(session):
    """mapupdate update's defaults grow the map into the unknown: its hit buffers are made in
    tiles where the scans hit open unknown space, not two bytes for every cell."""
    ref, scans, _ = session
    updater = MapUpdater(embedded(unknown_corner(ref), SIZE),
                         UpdaterConfig.profile("robot"))
    for scan, noisy, true in scans:
        updater.process(scan, noisy, odometry=true)
    assert updater._hits.used > 0 and len(updater.drawn_cells()[0]) > 0   # it grew
    assert updater.state_bytes() <= BAR_BYTES


def reference_hit_push(buffers, open_unknown, hits, changed, mask, threshold, few):
    """The hit buffers' rule written out on a dense array: a 0 for each cell seen through
    whose buffer holds something (and that is open unknown), then a 1 for each cell hit."""
    for idx in changed:
        if buffers[idx] and open_unknown[idx]:
            buffers[idx] = (buffers[idx] << 1) & mask
    for idx in hits:
        buffers[idx] = ((buffers[idx] << 1) | 1) & mask
    n = np.array([bin(int(b)).count("1") for b in buffers])
    only_hits = np.array([(int(b) & (int(b) + 1)) == 0 for b in buffers])
    return (n >= threshold) | ((n >= few) & only_hits)


def test_tiled_hit_buffers_follow_a_plain_dense_rule_to_the_edges_of_the_map():
    rng = np.random.default_rng(3)
    shape = (130, 200)                       # neither side a whole number of tiles
    ref = rng.choice(np.array([UNKNOWN, 0, 100], np.int8), size=shape, p=[0.6, 0.3, 0.1])
    cfg = UpdaterConfig.profile("robot")
    mask = steps.buffer_mask(cfg)
    tiles = HitTiles(shape)
    enclosed = np.zeros((ref.size + 7) // 8, np.uint8)
    drawn, marks = np.zeros_like(enclosed), np.zeros_like(enclosed)
    dense = np.zeros(ref.size, np.int64)
    open_unknown = ref.reshape(-1) == UNKNOWN
    ws = steps.Workspace()
    # few cells, so that buffers fill and empty again; some in the last rows and columns
    pick = np.concatenate([rng.choice(ref.size, 40, replace=False),
                           ref.size - 1 - np.arange(5), np.arange(5) * shape[1] + shape[1] - 1])
    for _ in range(60):
        hits = np.unique(rng.choice(pick[open_unknown[pick]], 6))
        seen = np.setdiff1d(np.unique(rng.choice(pick, 12)), hits)
        ws.hits_unknown, ws.changed = hits.astype(np.int64), seen.astype(np.int64)
        steps.push_hits(tiles, ref, enclosed, hits.size, seen.size, cfg, 0.05, marks, drawn, ws)
        want = reference_hit_push(dense, open_unknown, hits, seen, mask, cfg.threshold,
                                  cfg.unanimous_min)
        assert np.array_equal(tiles.dense().reshape(-1), dense)
        bits = np.unpackbits(drawn, bitorder="little")[:ref.size].astype(bool)
        assert np.array_equal(bits, want & (dense > 0))
    assert tiles.used < tiles.directory.size            # not every tile was made
    again = HitTiles.from_dense(tiles.dense())
    assert np.array_equal(again.dense(), tiles.dense())


def test_tiles_made_in_the_kernel_are_those_hit_tiles_makes_and_none_without_room():
    """Both against the tile numbers written out below."""
    rng = np.random.default_rng(5)
    shape = (300, 450)                       # 5 x 8 tiles
    by_numpy, by_kernel = HitTiles(shape), HitTiles(shape)
    for tiles in (by_numpy, by_kernel):      # room for 8 tiles, 2 of them in use
        tiles.make(np.array([3, 17]))
        tiles.make(np.array([30, 31, 32, 33, 34, 35]))
        tiles.pool[2:] = 0
        tiles.directory.reshape(-1)[30:36] = -1
        tiles.count[0] = 2
    wanted = np.array([12, 5, 12, 39, 5, 0])     # repeats, unsorted, none made yet
    by_numpy.make(wanted)
    assert K.make_hit_tiles(by_kernel.directory, by_kernel.pool.shape[0], by_kernel.count,
                            wanted) == 0
    assert np.array_equal(by_kernel.directory, by_numpy.directory)
    assert by_kernel.used == by_numpy.used == 6
    # the new tiles in ascending order after the two in use, the others untouched
    want = np.full(by_kernel.directory.size, -1)
    want[[3, 17, 0, 5, 12, 39]] = np.arange(6)
    assert np.array_equal(by_kernel.directory.reshape(-1), want)
    # four new tiles with room for two: nothing is made, the caller grows the pool
    before = by_kernel.directory.copy()
    more = rng.choice(np.flatnonzero(before.reshape(-1) < 0), 4, replace=False)
    assert K.make_hit_tiles(by_kernel.directory, by_kernel.pool.shape[0], by_kernel.count,
                            np.concatenate([more, more[:1]])) == 5
    assert np.array_equal(by_kernel.directory, before) and by_kernel.used == 6


@pytest.mark.parametrize("buffer_size, threshold", [(10, 7), (12, 12), (11, 8)])
def test_packed_counts_are_a_plain_count_saturating_at_the_top_of_their_field(buffer_size,
                                                                             threshold):
    rng = np.random.default_rng(buffer_size)
    cfg = UpdaterConfig(buffer_size=buffer_size, threshold=threshold, unanimous_min=2)
    shift, mask = steps.count_shift(cfg), steps.buffer_mask(cfg)
    top = 0xFFFF >> shift
    cells = 40
    hist = np.zeros(cells, np.uint16)
    plain_flags, plain_count = np.zeros(cells, np.int64), np.zeros(cells, np.int64)
    marks = np.zeros((cells + 7) // 8, np.uint8), np.zeros((cells + 7) // 8, np.uint8)
    moved = np.zeros(2 * cells, np.int32)
    # cells flagged at different rates: some stay below T, some pass the field's top
    rates = np.linspace(0.02, 1.0, cells)
    ref = np.zeros(cells, np.int8)
    ref[::3] = 100          # occupied cells of M are watched by the unanimous rule's guard
    for _ in range(3 * top if top < 100 else 120):
        flagged = np.flatnonzero(rng.random(cells) < rates)
        is_changed = rng.random(flagged.size) < 0.6
        changed, unchanged = (flagged[is_changed].astype(np.int32),
                              flagged[~is_changed].astype(np.int32))
        K.push_flags(hist, np.zeros(0, np.uint8), ref, changed=changed, unchanged=unchanged,
                     mask=mask, threshold=threshold, few=2, ch_marks=marks[0],
                     un_marks=marks[1], out_moved=moved, shift=shift)
        for idx, flag in [(i, 1) for i in changed] + [(i, 0) for i in unchanged]:
            plain_flags[idx] = ((plain_flags[idx] << 1) | flag) & mask
            plain_count[idx] += 1
    assert (hist & mask).tolist() == plain_flags.tolist()
    assert (hist >> shift).tolist() == np.minimum(plain_count, top).tolist()
    assert top >= buffer_size and plain_count.max() > top >= (hist >> shift).max()
    assert (plain_count < threshold).any()


def test_no_count_field_where_the_buffer_leaves_too_few_bits():
    assert steps.count_shift(UpdaterConfig(buffer_size=12, threshold=7, unanimous_min=3)) == 12
    for n_b in (13, 16):
        cfg = UpdaterConfig(buffer_size=n_b, threshold=7, unanimous_min=3)
        assert steps.count_shift(cfg) == 0
        ref = OccupancyGrid(np.zeros((30, 40), np.int8), 0.05)
        assert MapUpdater(ref, cfg)._seen.shape == (30, 40)
    assert steps.count_shift(UpdaterConfig()) == 0       # the paper's rules count nothing


def same_run(updater, want: golden.Golden, scans) -> None:
    """The recorded reports of the code before (``updater``, this code, makes no flag where
    one would change nothing: fewer of them, never more), its output map, evidence and change
    counts."""
    for k, (scan, noisy, true) in enumerate(scans):
        got = golden.as_recorded(updater.process(scan, noisy, odometry=true).summary())
        recorded = dict(want.facts["reports"][k])
        for key in FLAG_KEYS:
            assert got.pop(key) <= recorded.pop(key)
        assert got == recorded
    assert len(scans) == len(want.facts["reports"])
    assert np.array_equal(updater.updated_map().data, want["map"])
    assert golden.as_recorded(updater.evidence_summary()) == want.facts["evidence"]
    assert np.array_equal(updater.change_counts(), want["change_counts"])


def format1_session():
    """The map and scans of the format-1 state file: its first half wrote the file."""
    ref, scans, _ = room_session(16.0, 1)
    return unknown_corner(ref), scans


def test_the_format_1_state_file_is_one_of_the_layout_before():
    """The fixture: the flags alone in the buffers, counts past the packed field's top in its
    ``seen``, no checksums, and ``ROBOT_AS_BEFORE`` as its configuration."""
    with np.load(STATE_FORMAT_1, allow_pickle=False) as z:
        meta = json.loads(str(z["meta"]))
        assert meta["format"] == 1 and "checksums" not in meta
        assert "seen" in z.files and not np.any(z["hist"] >> 10)
        assert z["seen"].max() > 0xFFFF >> 10
    same_config(UpdaterConfig(**ROBOT_AS_BEFORE), meta["config"])


def test_a_state_of_the_layout_before_loads_and_continues_alike(tmp_path):
    ref, scans = format1_session()
    want = golden.Golden("updater_state_format1_continued")
    want.check_inputs(golden.fingerprint(ref.data, scans))
    loaded = MapUpdater.load(STATE_FORMAT_1)
    assert loaded._seen.size == 0
    same_run(loaded, want, scans[len(scans) // 2:])
    # saved in the new layout, loaded again: the same state
    loaded.save(tmp_path / "new.npz")
    again = MapUpdater.load(tmp_path / "new.npz")
    assert np.array_equal(again._hist, loaded._hist)
    assert again.evidence_summary() == loaded.evidence_summary()


def test_a_state_that_does_not_fit_is_refused_in_one_line(tmp_path):
    """The format-1 state with the flag counts of another map (a column fewer), written as
    the code before wrote its states (no checksums to refuse it first)."""
    with np.load(STATE_FORMAT_1, allow_pickle=False) as z:
        arrays = {name: z[name] for name in z.files}
    arrays["seen"] = arrays["seen"][:, :-1].copy()
    np.savez_compressed(tmp_path / "bad.npz", **arrays)
    with pytest.raises(UpdaterError, match="flag counts do not fit") as err:
        MapUpdater.load(tmp_path / "bad.npz")
    assert "\n" not in str(err.value)


def twin_session():
    ref, scans, _ = room_session(4.0, 3)
    return ref, scans


@pytest.mark.parametrize("buffer_size", [10, 14])
def test_a_state_of_either_layout_saves_and_loads_as_it_was(tmp_path, buffer_size):
    """Saved half way and loaded, the updater goes on as the code before went on from the
    same scans (with N_b = 14 the counts are kept apart, not packed)."""
    ref, scans = twin_session()
    config = UpdaterConfig(**{**ROBOT_AS_BEFORE, "buffer_size": buffer_size})
    want = golden.Golden(f"updater_twin_buffer{buffer_size}")
    want.check_inputs(golden.fingerprint(ref.data, scans))
    same_config(config, want.facts["config"])
    updater = MapUpdater(ref, config)
    half = len(scans) // 2
    for scan, noisy, true in scans[:half]:
        updater.process(scan, noisy, odometry=true)
    updater.save(tmp_path / "s.npz")
    loaded = MapUpdater.load(tmp_path / "s.npz")
    assert np.array_equal(loaded._hist, updater._hist)
    assert np.array_equal(loaded._seen, updater._seen)
    same_run(loaded, want, scans[half:])
