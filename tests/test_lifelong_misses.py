"""Why the faces rule drew none of a lifelong run's cells left to draw
(``benchmarks/lifelong_misses.draw_reasons``), on a hand-made map and hand-set counts whose
answer is worked out cell by cell below."""

import dataclasses

import numpy as np

from benchmarks import lifelong_misses as lm
from gridmap import FREE, OCCUPIED, UNKNOWN
from updater import UpdaterConfig
from updater.faces import FaceCounts

CFG = dataclasses.replace(UpdaterConfig.profile("robot"), face_band=4, face_min_hits=4,
                          face_large_min_hits=5, face_draw_ratio=0.34, face_max_area=1.0,
                          face_draw_beside_large=True, face_draw_sessions=2)
RES = 0.05


def _room():
    """60 x 60 cells at 5 cm: a wall of 480 cells along the top (rows 0-7: larger than 1 m^2),
    a 2 x 2 box at rows 40-41, columns 40-41, and a 3 x 3 patch of unknown cells 2-4 cells in
    front of the wall."""
    ref = np.full((60, 60), FREE, np.int8)
    ref[:8, :] = OCCUPIED
    ref[40:42, 40:42] = OCCUPIED
    ref[9:12, 29:32] = UNKNOWN
    return ref


def _bits(cells, shape):
    plane = np.zeros(shape, bool)
    for rc in cells:
        plane[rc] = True
    return np.packbits(plane.reshape(-1), bitorder="little")


def test_each_left_cell_gets_the_first_draw_condition_it_misses():
    ref = _room()
    hits, passes = np.zeros(ref.shape, np.uint8), np.zeros(ref.shape, np.uint8)
    # halved counts: a cell's hits this session were at most 2h + 1, its crossings at least 2p
    hits[40, 44], passes[40, 44] = 3, 4      # 7 hits at most, 8 crossings at least: crossed
    hits[37, 40] = 3                          # enough, never crossed, a candidate: waiting
    hits[40, 36] = 3                          # enough, never crossed, not a candidate: other
    hits[10, 20] = 1                          # 3 hits at most, 5 needed before the wall
    left_cells = {(25, 20): "reach",          # 12 cells from anything M has
                  (10, 30): "reach",          # unknown in front of the wall: never drawn
                  (44, 40): "hits",           # 3 from the box, counted nowhere near
                  (10, 20): "hits",
                  (40, 44): "crossed", (37, 40): "waiting", (40, 36): "other"}
    counts = FaceCounts(hits, passes, np.zeros(ref.shape, np.uint8), None,
                        _bits([(37, 40)], ref.shape))
    left = np.zeros(ref.shape, bool)
    for rc in left_cells:
        left[rc] = True
    got = lm.draw_reasons(ref, left, counts, CFG, RES)
    want = dict.fromkeys(["uncounted"] + [k for _, k in lm.REASONS], 0)
    for reason in left_cells.values():
        want[reason] += 1
    assert got == want
    # drawing on one session's word, no cell waits: the candidate is "other"
    got = lm.draw_reasons(ref, left, counts, dataclasses.replace(CFG, face_draw_sessions=1), RES)
    want["waiting"], want["other"] = 0, want["other"] + 1
    assert got == want


def test_before_the_wall_five_hits_are_needed_beside_the_box_four():
    ref = _room()
    hits = np.zeros(ref.shape, np.uint8)
    hits[10, 20] = 2            # at most 5: enough before the wall
    hits[44, 40] = 1            # at most 3 beside the box: short of its 4
    left = np.zeros(ref.shape, bool)
    left[10, 20] = left[44, 40] = True
    counts = FaceCounts(hits, np.zeros_like(hits), np.zeros_like(hits), None,
                        _bits([], ref.shape))
    got = lm.draw_reasons(ref, left, counts, CFG, RES)
    assert (got["hits"], got["other"]) == (1, 1)
    no_large = dataclasses.replace(CFG, face_draw_beside_large=False)
    got = lm.draw_reasons(ref, left, counts, no_large, RES)
    assert (got["reach"], got["hits"]) == (1, 1)


def test_a_session_that_counted_nothing_leaves_every_cell_uncounted():
    ref = _room()
    left = np.zeros(ref.shape, bool)
    left[44, 40] = left[25, 20] = True
    empty = FaceCounts.start(ref.shape, False, None)
    got = lm.draw_reasons(ref, left, empty, CFG, RES)
    assert got["uncounted"] == 2 and sum(got.values()) == 2
    assert lm.draw_reasons(ref, left, None, CFG, RES)["uncounted"] == 2


def test_the_cells_it_finds_past_every_condition_are_the_rules_own_candidates():
    """The faces rule's kernel, given the session's counts the halved ones stand for (2h + 1
    hits, 2p crossings), makes candidates of exactly the counted cells that ``draw_reasons``
    finds in reach, hit enough and seldom crossed."""
    from updater.faces import small_structure_bits
    from updater.steps import kernels

    ref = _room()
    hits, passes = np.zeros(ref.shape, np.uint8), np.zeros(ref.shape, np.uint8)
    hits[40, 44], passes[40, 44] = 3, 4
    hits[37, 40] = hits[40, 36] = 3
    hits[10, 20] = 1
    hits[10, 24] = 2
    hits[10, 30] = 3            # unknown in front of the wall
    counted = hits > 0
    shape, n = ref.shape, ref.size
    session = (hits * 2 + 1) * counted, passes * 2, np.zeros(shape, np.uint8)
    now = _bits([tuple(rc) for rc in np.argwhere(counted)], shape)
    planes = (now, np.zeros_like(now), np.zeros_like(now), np.zeros((n + 7) // 8, np.uint8),
              small_structure_bits(ref, CFG.face_max_area, RES))
    kernels().move_faces(ref, ref.copy(), tuple(a.astype(np.uint8) for a in session), planes,
                         CFG.face_band, CFG.face_min_passes, CFG.face_free_ratio,
                         CFG.face_min_hits, CFG.face_draw_ratio, (True, True, True),
                         CFG.face_draw_beside_large, CFG.face_large_min_hits)
    candidates = np.unpackbits(planes[3], bitorder="little")[:n].reshape(shape).astype(bool)
    counts = FaceCounts(hits, passes, np.zeros(shape, np.uint8), None, _bits([], shape))
    past = []
    for rc in map(tuple, np.argwhere(counted)):
        left = np.zeros(shape, bool)
        left[rc] = True
        if lm.draw_reasons(ref, left, counts, CFG, RES)["other"]:
            past.append(rc)
    assert sorted(past) == sorted(map(tuple, np.argwhere(candidates)))
    assert sorted(past) == [(10, 24), (37, 40), (40, 36)]


def test_wrong_changes_are_sorted_by_what_the_truth_holds_there():
    """``tally_wrong`` on a hand-made session: each wrong change placed by hand in one kind,
    and right changes (a moved box's old place freed, its new face drawn, a cell drawn one
    off the truth's face) counted as changes only."""
    truth = np.full((40, 40), FREE, np.int8)
    truth[:3, :] = OCCUPIED                      # a wall that stood
    truth[20:28, 20:28] = OCCUPIED               # a box moved here this session
    truth[21:27, 21:27] = UNKNOWN                # its inside
    previous = truth.copy()
    previous[20:28, 20:28] = FREE                # M(i-1) had the box elsewhere ...
    previous[27, 27] = OCCUPIED                  # ... but for a corner
    previous[33, 33] = OCCUPIED                  # ... here
    kept = np.zeros(truth.shape, bool)
    kept[:3, :] = True
    people = np.zeros(truth.shape, bool)
    people[10:13, 30:33] = True
    updated = previous.copy()
    updated[33, 33] = FREE                       # right: the old place freed
    updated[20, 20:28] = OCCUPIED                # right: the new face drawn
    updated[19, 28] = OCCUPIED                   # right: a cell off the truth's face
    updated[2, 5] = FREE                         # wrong: the wall freed
    updated[27, 27] = FREE                       # wrong: the moved box freed
    updated[23, 23] = OCCUPIED                   # wrong: inside the box, 3 cells deep
    updated[17, 22] = OCCUPIED                   # wrong: 3 cells in front of the box
    updated[11, 31] = OCCUPIED                   # wrong: far, where a person walked
    updated[11, 5] = OCCUPIED                    # wrong: far, no one walked there
    counts = dict.fromkeys(["changes"] + [k for _, k in lm.WRONG], 0)
    lm.tally_wrong(counts, previous, updated, truth, kept, people)
    assert counts == {"changes": 16, "free_standing": 1, "free_moved": 1, "free_inside": 0,
                      "draw_inside": 1, "draw_near": 1, "draw_far": 2, "draw_people": 1}
