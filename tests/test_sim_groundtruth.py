"""The ground-truth map G: visible outlines occupied, reachable free space free, the rest
unknown, people never in it; moved objects show where they went."""

import math

import numpy as np
import pytest

import sim
from gridmap import FREE, OCCUPIED, UNKNOWN
from sim import geometry as geo
from sim.groundtruth import covered_cells


def scenario(movable=(), sessions=None, bounds=(0.0, 0.0, 4.0, 3.0), people=()):
    sessions = sessions or [{"name": "S1", "route": [[0.6, 0.6]], "people": list(people)}]
    return sim.scenario_from_dict({
        "name": "room", "resolution": 0.05,
        "world": {"bounds": list(bounds), "wall_thickness": 0.1, "movable": list(movable)},
        "robot": {"start": [0.5, 0.5, 0.0], "radius": 0.2,
                  "lidars": [{"fov_deg": 270, "beams": 271, "range_max": 10.0}]},
        "sessions": sessions})


def cells_of(grid, x0, y0, x1, y1):
    """Index box (rows, cols) of the cells inside a cell-aligned rectangle [m]."""
    r0, c0 = grid.world_to_cell(x0 + 1e-9, y0 + 1e-9)
    r1, c1 = grid.world_to_cell(x1 - 1e-9, y1 - 1e-9)
    return slice(int(r0), int(r1) + 1), slice(int(c0), int(c1) + 1)


def ring(mask_shape, rows, cols):
    m = np.zeros(mask_shape, bool)
    m[rows, cols] = True
    inner = np.zeros(mask_shape, bool)
    inner[rows.start + 1:rows.stop - 1, cols.start + 1:cols.stop - 1] = True
    return m & ~inner, inner


def test_grid_frame_covers_the_walls_with_a_margin_on_round_coordinates():
    scn = sim.load_scenario("scenarios/aws_small_warehouse.yaml")
    frame = sim.grid_frame(scn)
    x0, y0, x1, y1 = frame.extent()
    assert x0 <= -6.85 - 0.13 - 0.05 and y0 <= -10.32 - 0.13 - 0.05
    assert x1 >= 6.85 + 0.13 + 0.05 and y1 >= 10.32 + 0.13 + 0.05
    assert (frame.data == UNKNOWN).all() and frame.resolution == 0.05
    for o in frame.origin:
        assert abs(o / 0.05 - round(o / 0.05)) < 1e-9


def test_room_with_one_box_has_exactly_its_outline_occupied_and_interior_unknown():
    scn = scenario([{"id": "box", "center": [2.5, 1.5], "size": [1.0, 0.6]}])
    g = sim.World(scn, 0).ground_truth()
    assert g.same_frame(sim.grid_frame(scn))
    box_rows, box_cols = cells_of(g, 2.0, 1.2, 3.0, 1.8)
    box_outline, box_inside = ring(g.shape, box_rows, box_cols)
    room_rows, room_cols = cells_of(g, 0.0, 0.0, 4.0, 3.0)
    wall_faces, _ = ring(g.shape, *cells_of(g, -0.05, -0.05, 4.05, 3.05))   # corners too
    occupied = g.data == OCCUPIED
    np.testing.assert_array_equal(occupied, box_outline | wall_faces)
    assert (g.data[box_inside] == UNKNOWN).all() and box_inside.sum() == 18 * 10
    free = np.zeros(g.shape, bool)
    free[room_rows, room_cols] = True
    free &= ~(box_outline | box_inside)
    np.testing.assert_array_equal(g.data == FREE, free)
    assert (g.data[~(free | occupied)] == UNKNOWN).all()


def test_moved_pallet_shows_where_it_went_not_where_it_was():
    pallet = {"id": "pallet", "center": [1.6, 1.6], "size": [1.2, 0.8]}
    scn = scenario([pallet], sessions=[
        {"name": "S1", "route": [[0.6, 0.6]]},
        {"name": "S2", "route": [[0.6, 0.6]], "changes": [{"move": "pallet", "to": [3.0, 2.0, 0.0]}]},
    ], bounds=(0.0, 0.0, 4.0, 3.0))
    g1 = sim.World(scn, "S1").ground_truth()
    g2 = sim.World(scn, "S2").ground_truth()
    old = cells_of(g1, 1.0, 1.2, 2.2, 2.0)
    new = cells_of(g2, 2.4, 1.6, 3.6, 2.4)
    old_outline, old_inside = ring(g1.shape, *old)
    new_outline, new_inside = ring(g2.shape, *new)
    assert (g1.data[old_outline] == OCCUPIED).all() and (g1.data[old_inside] == UNKNOWN).all()
    assert (g2.data[old_outline | old_inside] == FREE).all()
    assert (g2.data[new_outline] == OCCUPIED).all() and (g2.data[new_inside] == UNKNOWN).all()
    assert (g1.data[new_outline | new_inside] == FREE).all()


def test_people_are_never_part_of_the_ground_truth():
    scn = scenario(people=[{"wander": [1.0, 1.0, 3.5, 2.5], "count": 3}])
    world = sim.World(scn, 0)
    assert len(world.people()) == 3
    empty = sim.World(scenario(), 0).ground_truth()
    np.testing.assert_array_equal(world.ground_truth().data, empty.data)


def test_unreachable_space_is_unknown():
    # a closed box ring around a pocket: the pocket's cells are outside the free space
    walls = [{"id": f"w{k}", "center": c, "size": s} for k, (c, s) in enumerate([
        ([3.0, 1.0], [1.0, 0.1]), ([3.0, 2.0], [1.0, 0.1]),
        ([2.45, 1.5], [0.1, 0.9]), ([3.55, 1.5], [0.1, 0.9])])]
    g = sim.World(scenario(walls), 0).ground_truth()
    pocket = cells_of(g, 2.5, 1.05, 3.5, 1.95)
    assert (g.data[pocket] == UNKNOWN).all()


def test_rotated_box_and_circle_cover_the_cells_they_share_area_with():
    frame = sim.grid_frame(scenario())
    box = np.array([[2.013, 1.477, 0.61, 0.27, 0.7]])
    circle = np.array([[1.0, 2.0, 0.33]])
    cover = covered_cells(frame, box, circle)
    # reference: 20 x 20 sample points inside each cell
    rows, cols = np.nonzero(np.ones(frame.shape, bool))
    x0, y0 = frame.cell_to_world(rows, cols)
    res = frame.resolution
    offs = (np.arange(20) + 0.5) / 20 * res - res / 2
    sx = (x0[:, None, None] + offs[None, :, None]).repeat(20, axis=2).reshape(-1)
    sy = (y0[:, None, None] + offs[None, None, :]).repeat(20, axis=1).reshape(-1)
    pts = np.column_stack([sx, sy])
    inside = (geo.point_box_distance(pts, box)[:, 0] < 0) | \
        (geo.point_circle_distance(pts, circle)[:, 0] < 0)
    sampled = inside.reshape(-1, 400).any(axis=1).reshape(frame.shape)
    assert (cover | ~sampled).all()                       # every sampled cell is covered
    extra = cover & ~sampled                              # covered, no sample inside: a sliver
    cx, cy = frame.cell_to_world(*np.nonzero(extra))
    d = np.minimum(geo.point_box_distance(np.column_stack([cx, cy]), box)[:, 0],
                   geo.point_circle_distance(np.column_stack([cx, cy]), circle)[:, 0])
    assert (d < res * math.sqrt(2) / 2).all() and extra.sum() < 0.1 * cover.sum()


def test_flood_fill_kernel_matches_a_dilation_reference():
    from sim._kernels import flood_fill4

    rng = np.random.default_rng(4)
    passable = rng.random((60, 80)) > 0.35
    passable[30, 40] = True
    got = np.zeros_like(passable)
    flood_fill4(passable, 30, 40, got)
    ref = np.zeros_like(passable)
    ref[30, 40] = True
    while True:
        grown = ref.copy()
        grown[1:] |= ref[:-1]
        grown[:-1] |= ref[1:]
        grown[:, 1:] |= ref[:, :-1]
        grown[:, :-1] |= ref[:, 1:]
        grown &= passable
        if (grown == ref).all():
            break
        ref = grown
    np.testing.assert_array_equal(got, ref)


def test_built_in_warehouse_truth_is_a_closed_building():
    scn = sim.load_scenario("scenarios/aws_small_warehouse.yaml")
    g = sim.World(scn, "W1").ground_truth()
    c = g.counts()
    assert c["free"] > 0.6 * (13.7 * 20.64) / 0.05 ** 2
    assert c["occupied"] > 2000
    # nothing free outside the walls
    rows, cols = np.nonzero(g.data == FREE)
    x, y = g.cell_to_world(rows, cols)
    assert x.min() > -6.85 and x.max() < 6.85 and y.min() > -10.32 and y.max() < 10.32
    with pytest.raises(sim.ScenarioError):
        sim.World(scn, "W9")
