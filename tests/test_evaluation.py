"""Session scores on small grids worked out by hand."""

import math

import numpy as np
import pytest

from gridmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid, Pose2D, Scan
import evaluation as ev

F, O, U = FREE, OCCUPIED, UNKNOWN


def grid(rows):
    return OccupancyGrid(np.array(rows, np.int8), 1.0)


def test_near_is_one_cell_eight_neighbourhood():
    m = np.zeros((5, 5), bool)
    m[2, 2] = True
    assert ev.near(m).sum() == 9
    assert ev.near(m)[1, 1] and ev.near(m)[3, 3] and not ev.near(m)[0, 2]


def test_change_detection_counts_by_hand():
    # A box (column 3) was removed and a box appeared at column 0, row 1.
    prev = grid([[F, F, F, O, F, F],
                 [F, F, F, O, F, F],
                 [F, F, F, O, F, F]])
    true = grid([[F, F, F, F, F, F],
                 [O, F, F, F, F, F],
                 [F, F, F, F, F, F]])
    upd = grid([[F, F, F, F, F, F],      # two of the three removed cells freed
                [O, F, F, F, F, F],      # the new cell added
                [F, F, F, O, F, O]])     # one removal missed, one false obstacle at (2, 5)
    observable = np.ones(prev.shape, bool)
    cd = ev.change_detection(prev, upd, true, observable)
    # changes: (0,3), (1,3) freed, (1,0) added, (2,5) added; correct: the first three.
    assert cd["changes"] == 4 and cd["correct_changes"] == 3
    assert cd["precision"] == pytest.approx(0.75)
    # targets: the three occupied cells of column 3 and the new cell (1, 0): 4; fixed: 3.
    assert cd["target_cells"] == 4 and cd["targets_fixed"] == 3
    assert cd["recall"] == pytest.approx(0.75)
    assert cd["f1"] == pytest.approx(0.75)
    assert cd["recall_all"] == pytest.approx(0.75)


def test_slack_of_one_cell_forgives_an_outline_one_cell_off():
    prev = grid([[F, O, F, F]])
    true = grid([[F, F, O, F]])   # the wall sits one cell further: nothing is wrong
    wo, wf = ev.wrong_cells(prev, true)
    assert not wo.any() and not wf.any()


def test_targets_outside_the_observable_cells_count_only_in_recall_all():
    prev = grid([[O, F, F, F, O]])
    true = grid([[F, F, F, F, F]])
    upd = grid([[F, F, F, F, O]])
    observable = np.array([[True, True, True, False, False]])
    cd = ev.change_detection(prev, upd, true, observable)
    assert cd["target_cells"] == 1 and cd["recall"] == 1.0
    assert cd["recall_all"] == pytest.approx(0.5)


def test_no_changes_gives_no_precision_rather_than_a_made_up_number():
    g = grid([[F, O], [F, F]])
    cd = ev.change_detection(g, g, g, np.ones((2, 2), bool))
    assert cd["precision"] is None and cd["changes"] == 0


def test_ghosts_are_occupied_cells_far_from_truth_that_a_person_covered():
    true = grid([[F, F, F, F, F, O]])
    upd = grid([[O, F, O, F, O, O]])
    people = np.array([[True, True, False, False, True, True]])
    # (0,0) covered and far: ghost; (0,2) not covered; (0,4) near the wall at (0,5).
    assert ev.ghost_cells(upd, true, people) == 1


def test_oracle_sets_exactly_the_observable_targets():
    prev = grid([[O, F, F, F, O]])
    true = grid([[F, F, F, F, F]])
    observable = np.array([[True, True, True, False, False]])
    oracle = ev.oracle_map(prev, true, observable)
    assert oracle.data.tolist() == [[F, F, F, F, O]]


def test_ape_statistics_match_hand_values():
    est = [[0, 0], [3, 4], [1, 0]]
    true = [[0, 0], [0, 0], [0, 0]]
    s = ev.ape_statistics(est, true)      # errors 0, 5, 1
    assert s["max"] == 5 and s["min"] == 0 and s["median"] == 1
    assert s["mean"] == pytest.approx(2.0)
    assert s["sse"] == pytest.approx(26.0)
    assert s["rmse"] == pytest.approx(math.sqrt(26 / 3))
    assert s["std"] == pytest.approx(np.std([0, 5, 1]))


def test_observation_counter_counts_each_cell_once_per_scan():
    frame = OccupancyGrid.empty(40, 40, 0.1, (0.0, 0.0))
    counter = ev.ObservationCounter(frame, max_range=1.0)
    pose = Pose2D(0.05, 2.05, 0.0)
    for _ in range(7):
        # two beams along the same row: a cell still counts once per scan
        counter.add_scan(pose, np.array([0.5, 0.5]), np.array([0.0, 1e-4]))
    obs = counter.observable(7)
    assert obs[20, 0:6].all()              # sensor cell to the hit cell at x = 0.55
    assert counter.counts[20, 3] == 7
    assert not obs[20, 7:].any() and not obs[19].any()
    # an inf beam passes through up to the observation range
    counter.add_scan(pose, np.array([np.inf]), np.array([0.0]))
    assert counter.counts[20, 10] == 1 and counter.counts[20, 11] == 0


def test_scan_hit_counts_counts_each_cell_once_per_scan():
    frame = OccupancyGrid.empty(40, 40, 0.1, (0.0, 0.0))
    scan = Scan(np.array([0.52, 0.53, np.nan, 5.0]), 0.0, 1e-4, 0.1, 10.0)
    counts = ev.scan_hit_counts(frame, [(scan, Pose2D(0.05, 2.05, 0.0))] * 3, max_range=1.0)
    # two beams end in the cell at x = 0.57 (column 5), the NaN and the beam past max_range
    # end nowhere
    assert counts[20, 5] == 3 and counts.sum() == 3


def test_growth_scores_count_walls_as_structures_the_later_scans_still_hit():
    # before: a wall (row 1, columns 0-3) and a lone cell (row 3, column 4); the update frees
    # wall cell (1, 2) and the lone cell, the whole map keeps both; the later scans hit the
    # wall cell only
    before = grid([[F, F, F, F, F, F],
                   [O, O, O, O, F, F],
                   [F, F, F, F, F, F],
                   [F, F, F, F, O, F]])
    after = grid([[F, F, F, F, F, F],
                  [O, O, F, O, F, F],
                  [F, F, F, F, F, F],
                  [F, F, F, F, F, F]])
    counts = np.full((4, 6), 10)
    hits = np.zeros((4, 6), int)
    hits[1, 2] = 2
    g = ev.growth_scores(before, after, before, counts, hits=hits)
    assert g["freed"] == 2 and g["freed_also_in_whole"] == 2 and g["walls_freed"] == 1
    hits[1, 2] = 0           # a structure the later scans never hit: gone, not a wall
    assert ev.growth_scores(before, after, before, counts, hits=hits)["walls_freed"] == 0
    assert "walls_freed" not in ev.growth_scores(before, after, before, counts)


def test_paint_people_marks_cell_centres_inside_the_disc():
    frame = OccupancyGrid.empty(10, 10, 1.0, (0.0, 0.0))
    mask = np.zeros(frame.shape, bool)
    ev.paint_people(mask, frame, np.array([[5.0, 5.0, 1.0]]))
    # centres (4.5|5.5, 4.5|5.5) are within 0.71 m; (3.5, 5.5) is 1.58 m away
    assert mask.sum() == 4 and mask[4:6, 4:6].all()
