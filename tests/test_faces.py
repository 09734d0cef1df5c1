"""The faces rule (``UpdaterConfig.move_faces``, updater/_faces.py): a face of M a few cells off
the world's is moved to where the scans see it; walls seen from far or grazed stay."""

import json
import math

import numpy as np
import pytest

import synthetic_room as world
from gridmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid, Pose2D
from synthetic_room import Rect
from updater import FaceCounts, MapUpdater, UpdaterConfig, UpdaterError
from updater.steps import kernels

# a box whose face M has 0.1 m (two cells) from where it stands
OLD = Rect(7.0125, 3.0125, 7.6125, 3.6125)
NEW = Rect(7.1125, 3.1125, 7.7125, 3.7125)


def _config(**keys):
    """The robot profile with the rule acting in the session itself (face_sessions 1), on the
    drive's poses as given (no pose check to place them)."""
    return UpdaterConfig.profile("robot", {"move_faces": True, "face_sessions": 1,
                                           "face_refined_only": False, **keys})


def _walls() -> np.ndarray:
    walls = np.zeros(world.rasterise(world.room_walls()).shape, bool)
    for w in world.room_walls():
        walls |= world.cells_of(w)
    return walls


def _drive(ref, shapes, config, faces=None, seed=1, seconds=40.0, **drive):
    up = MapUpdater(ref, config, faces=faces)
    for true, noisy, t in world.Drive(seconds=seconds, seed=seed, **drive).steps():
        up.process(world.full_scan(shapes, true, t), noisy, odometry=true)
    return up


# --- the counts against a reference written from the rule's words -----------------------------
def _reference_counts(points, sensor, band, min_sine, shape):
    """Hits: the cell each valid hit lies in, once per scan. Passes: for a beam whose hit and
    its neighbours' two beams away are valid and lie within 8 cells of each other, and which
    meets the line through those neighbours at a sine of ``min_sine`` or more, the cells of
    the points 1/4, 2/4, ... ``band`` cells short of its hit along the beam (before the
    sensor), but for its own hit cell and any cell a beam of the scan ends in or stands
    behind; once per scan. Behind: the cells of the points 1/4 ... ``band`` cells past a valid
    hit along its beam, but for its own hit cell and the hit cells; once per scan."""
    height, width = shape
    hits, passes = np.zeros(shape, int), np.zeros(shape, int)
    hit_cells = set()
    for x, y in points:
        if not math.isnan(x) and 0 <= int(math.floor(x)) < width \
                and 0 <= int(math.floor(y)) < height:
            hit_cells.add((int(math.floor(y)), int(math.floor(x))))
    for r, c in hit_cells:
        hits[r, c] += 1
    behind_cells = set()
    for x, y in points:
        d = np.array([x - sensor[0], y - sensor[1]])
        if math.isnan(x) or np.linalg.norm(d) == 0:
            continue
        u = d / np.linalg.norm(d)
        own = (int(math.floor(y)), int(math.floor(x)))
        for k in range(1, 4 * band + 1):
            cell = (int(math.floor(y + k / 4 * u[1])), int(math.floor(x + k / 4 * u[0])))
            if cell != own and 0 <= cell[0] < height and 0 <= cell[1] < width:
                behind_cells.add(cell)
    behind = np.zeros(shape, int)
    for r, c in behind_cells - hit_cells:
        behind[r, c] += 1
    crossed = set()
    for i in range(2, len(points) - 2):
        (x, y), (xa, ya), (xb, yb) = points[i], points[i - 2], points[i + 2]
        if any(math.isnan(v) for v in (x, xa, xb)):
            continue
        t = np.array([xb - xa, yb - ya])
        d = np.array([x - sensor[0], y - sensor[1]])
        if not 0 < np.linalg.norm(t) <= 8 or np.linalg.norm(d) == 0:
            continue
        u = d / np.linalg.norm(d)
        if abs(u[0] * t[1] - u[1] * t[0]) / np.linalg.norm(t) < min_sine:
            continue
        own = (int(math.floor(y)), int(math.floor(x)))
        for k in range(1, 4 * band + 1):
            s = k / 4
            if s >= np.linalg.norm(d):
                break
            cell = (int(math.floor(y - s * u[1])), int(math.floor(x - s * u[0])))
            if cell != own and 0 <= cell[0] < height and 0 <= cell[1] < width:
                crossed.add(cell)
    for r, c in crossed - hit_cells - behind_cells:
        passes[r, c] += 1
    return hits, passes, behind


def test_counts_follow_the_rule_as_written():
    rng = np.random.default_rng(4)
    shape = (60, 80)
    sensor = np.array([40.3, 30.7, 0.0])
    # beams onto a wall (steep), along a wall (grazing), scattered, and a few invalid ones
    angles = np.linspace(-2.5, 2.5, 200)
    ranges = np.where(np.abs(np.cos(angles)) > 0.2, 25.0 / np.maximum(np.abs(np.cos(angles)),
                                                                      1e-9), 30.0)
    ranges = np.minimum(ranges, 35.0) + rng.normal(0, 0.4, angles.size)
    points = np.column_stack([sensor[0] + ranges * np.cos(angles),
                              sensor[1] + ranges * np.sin(angles)])
    points[rng.choice(angles.size, 12, replace=False)] = np.nan
    for band, min_sine in ((4, 0.5), (2, 0.0), (6, 0.9)):
        hits, passes, behind = (np.zeros(shape, np.uint8) for _ in range(3))
        marks = np.zeros((shape[0] * shape[1] + 7) // 8, np.uint8)
        now, crossed = marks.copy(), marks.copy()
        listed = np.zeros(points.shape[0] * (8 * band + 1), np.int64)
        for _ in range(2):          # two scans: every count twice
            kernels().count_faces(points, sensor, band, min_sine, hits, passes, behind, marks,
                                  listed, now, crossed)
        want = _reference_counts(points, sensor, band, min_sine, shape)
        assert not marks.any()
        for plane, counts in ((now, want[0]), (crossed, want[1])):
            cells = np.unpackbits(plane, bitorder="little")[:hits.size].reshape(shape)
            assert np.array_equal(cells.astype(bool), counts > 0)
        for got, expected in zip((hits, passes, behind), want):
            assert np.array_equal(got, 2 * expected), band
            assert expected.sum() > 50


def test_move_faces_frees_crossed_cells_and_draws_hit_ones_near_a_surface():
    """The output rule on hand-made counts, cell by cell."""
    ref = np.full((12, 12), FREE, np.int8)
    ref[:, 3] = OCCUPIED          # a face
    ref[11, 11] = UNKNOWN
    hits, passes, behind = (np.zeros(ref.shape, np.uint8) for _ in range(3))
    passes[2, 3], hits[2, 3] = 10, 1          # crossed, hardly hit: freed
    passes[3, 3], hits[3, 3] = 10, 2          # hit a fifth of that: stays
    passes[1, 3], behind[1, 3] = 10, 2        # stood behind hits a fifth of that: stays
    passes[4, 3] = 4                          # crossed too few times: stays
    hits[2, 5], passes[2, 5] = 6, 2           # two cells from the face, hit: drawn
    hits[3, 5], passes[3, 5] = 6, 3           # crossed more than a third: not drawn
    hits[4, 4] = 9                            # one cell from the face: left to the map
    hits[5, 9] = 9                            # six cells from it: the paper's new obstacle
    hits[11, 11] = 9                          # unknown, far from the face: left
    hits[6, 7] = 9                            # four cells from it, unknown: drawn
    ref[6, 7] = UNKNOWN
    hits[7, 6] = 9                            # three cells from it, hit in earlier sessions only
    passes[6, 3] = 10                         # crossed in earlier sessions only: stays
    now = np.zeros(ref.size, np.uint8)
    now[np.flatnonzero(hits)] = 1
    now[7 * 12 + 6] = 0
    now = np.packbits(now, bitorder="little")
    crossed = np.zeros(ref.size, np.uint8)
    crossed[np.flatnonzero(passes)] = 1
    crossed[6 * 12 + 3] = 0
    crossed = np.packbits(crossed, bitorder="little")
    out = ref.copy()
    candidates = np.full_like(now, 0xFF)
    small = np.full_like(now, 0xFF)
    freed, drawn = kernels().move_faces(ref, out, (hits, passes, behind),
                                        (now, crossed, now * 0, candidates, small), 4, 5, 0.1, 5,
                                        0.34, (False, False, False), False, 5)
    assert (freed, drawn) == (1, 2)
    changed = {(int(r), int(c)): int(out[r, c]) for r, c in zip(*np.nonzero(out != ref))}
    assert changed == {(2, 3): FREE, (2, 5): OCCUPIED, (6, 7): OCCUPIED}
    bits = np.unpackbits(candidates, bitorder="little")[:ref.size].reshape(ref.shape)
    assert {(int(r), int(c)) for r, c in zip(*np.nonzero(bits))} == set(changed)
    # confirmed by the session before: only the cells it would have moved too
    confirmed = np.zeros(ref.size, np.uint8)
    confirmed[2 * 12 + 5] = 1
    confirmed[9 * 12 + 9] = 1                 # not a candidate now: stays
    out = ref.copy()
    planes = (now, crossed, np.packbits(confirmed, bitorder="little"), candidates, small)
    assert kernels().move_faces(ref, out, (hits, passes, behind), planes, 4, 5, 0.1, 5, 0.34,
                                (True, True, True), False, 5) == (0, 1)
    assert {(int(r), int(c)) for r, c in zip(*np.nonzero(out != ref))} == {(2, 5)}
    # the agreement asked of the frees only: every draw, the unconfirmed free stays
    out = ref.copy()
    assert kernels().move_faces(ref, out, (hits, passes, behind), planes, 4, 5, 0.1, 5, 0.34,
                                (True, False, True), False, 5) == (0, 2)
    assert {(int(r), int(c)) for r, c in zip(*np.nonzero(out != ref))} == {(2, 5), (6, 7)}
    # ... of the draws only: the free, and the one confirmed draw
    out = ref.copy()
    assert kernels().move_faces(ref, out, (hits, passes, behind), planes, 4, 5, 0.1, 5, 0.34,
                                (False, True, True), False, 5) == (1, 1)
    assert {(int(r), int(c)) for r, c in zip(*np.nonzero(out != ref))} == {(2, 3), (2, 5)}
    # a face of a large structure (a wall, a rack) stays, and nothing is drawn beside it ...
    out = ref.copy()
    planes = (now, crossed, now * 0, candidates, small * 0)
    assert kernels().move_faces(ref, out, (hits, passes, behind), planes, 4, 5, 0.1, 5, 0.34,
                                (False, False, False), False, 5) == (0, 0)
    # ... but with beside_large, in M's free space: an object set down in front of it (its
    # unknown, the inside of a wall or a rack, stays), when hit often enough for that too
    assert kernels().move_faces(ref, out, (hits, passes, behind), planes, 4, 5, 0.1, 5, 0.34,
                                (False, False, False), True, 7) == (0, 0)
    assert kernels().move_faces(ref, out, (hits, passes, behind), planes, 4, 5, 0.1, 5, 0.34,
                                (False, False, False), True, 6) == (0, 1)
    assert {(int(r), int(c)) for r, c in zip(*np.nonzero(out != ref))} == {(2, 5)}
    # a draw in front of it waits for the agreement asked of what stands there, not of objects
    planes = (now, crossed, np.packbits(confirmed * 0, bitorder="little"), candidates, small * 0)
    for confirm, moved in (((False, False, True), (0, 0)), ((True, True, False), (0, 1))):
        out = ref.copy()
        assert kernels().move_faces(ref, out, (hits, passes, behind), planes, 4, 5, 0.1, 5,
                                    0.34, confirm, True, 6) == moved


def test_small_structures_are_those_of_a_labelling():
    from scipy import ndimage

    from updater.faces import small_structure_bits

    rng = np.random.default_rng(3)
    ref = np.where(rng.random((70, 90)) < 0.3, OCCUPIED, FREE).astype(np.int8)
    ref[10, :] = OCCUPIED                        # a long wall
    labels, n = ndimage.label(ref == OCCUPIED, structure=np.ones((3, 3)))
    sizes = np.bincount(labels.ravel())
    for max_cells in (1, 5, 40):
        want = (labels > 0) & (sizes[labels] <= max_cells)
        bits = small_structure_bits(ref, max_cells * 0.05**2, 0.05)
        got = np.unpackbits(bits, bitorder="little")[:ref.size].reshape(ref.shape)
        assert np.array_equal(got.astype(bool), want), max_cells
        assert want.any() and (~want & (ref == OCCUPIED)).any()


# --- in a room ------------------------------------------------------------------------------
def test_a_face_two_cells_off_is_moved_to_where_the_scans_see_it():
    ref = world.rasterise(world.room_walls(), hollow=[OLD])
    truth = world.rasterise(world.room_walls(), hollow=[NEW]).data
    near_new = world.dilate(truth == OCCUPIED, 1)
    # the west faces, which the drive sees square on from the west half of its circle (the
    # south ones it sees at 17 degrees or less, as rays that graze them)
    west_old, west_new = np.zeros(truth.shape, bool), np.zeros(truth.shape, bool)
    west_old[:, int(OLD.x0 / world.RES)] = True
    west_new[:, int(NEW.x0 / world.RES)] = True
    old_face = (ref.data == OCCUPIED) & world.cells_of(OLD) & west_old & ~near_new
    new_face = (truth == OCCUPIED) & west_new & ~world.dilate(ref.data == OCCUPIED, 1)
    walls = _walls()
    shapes = world.room_walls() + [NEW]
    out = {}
    for on in (False, True):
        data = _drive(ref, shapes, _config(move_faces=on)).updated_map().data
        out[on] = {"old_freed": float((data[old_face] == FREE).mean()),
                   "new_drawn": float(world.dilate(data == OCCUPIED, 1)[new_face].mean()),
                   "false": int(((data == OCCUPIED) & (ref.data != OCCUPIED) & ~near_new).sum()),
                   "walls_freed": int(((data == FREE) & walls).sum())}
    assert old_face.sum() >= 10 and new_face.sum() >= 10
    assert out[True]["old_freed"] >= out[False]["old_freed"] + 0.5, out
    assert out[True]["old_freed"] >= 0.5 and out[True]["new_drawn"] >= 0.8, out
    assert out[True]["false"] <= 2 and out[True]["walls_freed"] == 0, out


@pytest.mark.parametrize("panel", [Rect(10.35, 4.5, 10.45, 6.5), Rect(0.55, 4.5, 0.65, 6.5)])
def test_a_board_set_down_in_front_of_a_wall_is_drawn(panel):
    """A board 10 cm thick, 5 cm in front of a wall that M has: its front face is 2-3 cells
    from the wall's, within tol(r) of it, where the paper draws nothing and the rest of the
    faces rule draws nothing beside a structure larger than ``face_max_area``. With
    ``face_draw_beside_large`` it is drawn, and nothing else is."""
    ref = world.rasterise(world.room_walls())
    shapes = world.room_walls() + [panel]
    truth = world.rasterise(shapes).data
    face = (truth == OCCUPIED) & world.cells_of(panel) & ~world.dilate(ref.data == OCCUPIED, 1)
    drawn = {}
    for on in (False, True):
        data = _drive(ref, shapes, _config(face_draw_beside_large=on)).updated_map().data
        drawn[on] = float(world.dilate(data == OCCUPIED, 1)[face].mean())
        assert not ((data == OCCUPIED) & (ref.data != OCCUPIED)
                    & ~world.dilate(truth == OCCUPIED, 1)).any()
        assert not ((data == FREE) & _walls()).any()
    assert face.sum() >= 60
    assert drawn[False] <= 0.1 and drawn[True] >= 0.9, drawn


def _two_sessions(ref, shapes, config, seed, **drive):
    """M(2) after two sessions of the drive, the counts carried from the first."""
    first = _drive(ref, shapes, config, seed=seed, **drive)
    return _drive(first.updated_map(), shapes, config, faces=first.carried_faces(),
                  seed=seed + 10, **drive).updated_map().data


def test_a_board_seen_in_passing_beside_a_box_is_drawn_on_fewer_hits():
    """A board set down 10 cm from a box that M has, passed by two short sessions: a face cell
    is hit by a few scans a session. With the profile's ``face_min_hits`` (4) and draws once
    two sessions agree, the second session draws more of its face than with 5, and nothing
    off a true surface (the profile's own draws, on one session's word: the next test)."""
    box, board = Rect(8.0125, 5.0125, 8.6125, 5.6125), Rect(7.8125, 5.0125, 7.9125, 5.6125)
    ref = world.rasterise(world.room_walls() + [box])
    shapes = world.room_walls() + [box, board]
    truth = world.rasterise(shapes).data
    face = (truth == OCCUPIED) & world.cells_of(board) & ~world.dilate(ref.data == OCCUPIED, 1)
    profile = UpdaterConfig.profile("robot").face_min_hits
    drawn = {profile: [], 5: []}
    for seconds, radius in ((10.0, 1.5), (6.0, 2.0)):
        for seed in range(1, 7):
            for hits in drawn:
                config = _config(face_sessions=2, face_draw_sessions=2, face_min_hits=hits)
                data = _two_sessions(ref, shapes, config, seed, seconds=seconds, radius=radius)
                drawn[hits].append(float(world.dilate(data == OCCUPIED, 1)[face].mean()))
                assert not ((data == OCCUPIED) & (ref.data != OCCUPIED)
                            & ~world.dilate(truth == OCCUPIED, 1)).any(), (seed, hits)
                assert not ((data == FREE) & _walls()).any()
    assert face.sum() >= 30
    mean = {hits: float(np.mean(d)) for hits, d in drawn.items()}
    assert profile == 4 and mean[4] >= 0.6 and mean[4] - mean[5] >= 0.08, mean


def test_drawing_on_one_sessions_word_draws_more_of_the_board_a_cell_further_at_most():
    """The same board and sessions with the profile's own draws beside objects
    (``face_draw_sessions`` 1; frees, and draws in front of walls, still once two sessions
    agree): more of the board's face is drawn than when those draws wait for the second
    session, and no cell more than two cells off a true surface (one cell two off in a dozen
    pairs of sessions is what the wait had kept out)."""
    box, board = Rect(8.0125, 5.0125, 8.6125, 5.6125), Rect(7.8125, 5.0125, 7.9125, 5.6125)
    ref = world.rasterise(world.room_walls() + [box])
    shapes = world.room_walls() + [box, board]
    truth = world.rasterise(shapes).data
    face = (truth == OCCUPIED) & world.cells_of(board) & ~world.dilate(ref.data == OCCUPIED, 1)
    profile = UpdaterConfig.profile("robot")
    assert (profile.face_sessions, profile.face_draw_sessions) == (2, 1)
    drawn, two_off = {1: [], 2: []}, {1: 0, 2: 0}
    for seconds, radius in ((10.0, 1.5), (6.0, 2.0)):
        for seed in range(1, 7):
            for sessions in drawn:
                config = _config(face_sessions=2, face_draw_sessions=sessions)
                data = _two_sessions(ref, shapes, config, seed, seconds=seconds, radius=radius)
                drawn[sessions].append(float(world.dilate(data == OCCUPIED, 1)[face].mean()))
                new = (data == OCCUPIED) & (ref.data != OCCUPIED)
                assert not (new & ~world.dilate(truth == OCCUPIED, 2)).any(), (seed, sessions)
                two_off[sessions] += int((new & ~world.dilate(truth == OCCUPIED, 1)).sum())
    mean = {sessions: float(np.mean(d)) for sessions, d in drawn.items()}
    assert mean[1] - mean[2] >= 0.1, mean
    assert two_off[2] == 0 and two_off[1] <= 3, two_off


def test_in_front_of_walls_a_cell_is_drawn_on_five_hits_still():
    """Walls alone, circled by two sessions with 2 cm / 1 deg of pose noise: grazing beams'
    hits land a cell or two in front of the walls. The profile draws there no more than with
    5 hits everywhere (``face_large_min_hits``); with 4 there too it draws cells a cell off."""
    ref = world.rasterise(world.room_walls())
    off_surface = ~world.dilate(ref.data == OCCUPIED, 1)
    drawn = {}
    for name, keys in (("profile", {}), ("5", {"face_min_hits": 5}),
                       ("4 everywhere", {"face_large_min_hits": 4})):
        drawn[name] = sum(int(((_two_sessions(ref, world.room_walls(),
                                              _config(face_sessions=2, **keys), seed,
                                              radius=4.4, seconds=20.0) == OCCUPIED)
                               & off_surface).sum()) for seed in (3, 5))
    # drawing beside objects on one session's word, in front of walls still on two
    two = sum(int(((_two_sessions(ref, world.room_walls(),
                                  _config(face_sessions=2, face_draw_sessions=2), seed,
                                  radius=4.4, seconds=20.0) == OCCUPIED) & off_surface).sum())
              for seed in (3, 5))
    assert drawn["profile"] == drawn["5"] == two < drawn["4 everywhere"], (drawn, two)


@pytest.mark.parametrize("radius, seed", [(4.4, 1), (4.7, 2), (1.5, 3)])
def test_walls_seen_from_near_far_or_grazed_stay_where_they_are(radius, seed):
    """Nothing moved: M is the world. Circling 0.3-1.1 m from the walls (rays graze them) or
    4 m away, with 2 cm / 1 deg of pose noise, the rule moves nothing: no wall cell freed, no
    cell drawn off a true surface."""
    ref = world.rasterise(world.room_walls())
    up = _drive(ref, world.room_walls(), _config(), seed=seed, radius=radius, seconds=60.0)
    off = _drive(ref, world.room_walls(), _config(move_faces=False), seed=seed, radius=radius,
                 seconds=60.0).updated_map().data
    data = up.updated_map().data
    assert not ((data == FREE) & _walls()).any()
    assert not ((data != off) & ~world.dilate(ref.data == OCCUPIED, 1)).any()
    assert up.carried_faces().passes.max() > 0      # the rule did look


def test_counts_go_on_into_the_next_session_halved():
    ref = world.rasterise(world.room_walls(), hollow=[OLD])
    shapes = world.room_walls() + [NEW]
    first = _drive(ref, shapes, _config(), seconds=10.0)
    carried = first.carried_faces()
    assert np.array_equal(carried.hits, first._faces.hits >> 1)
    assert np.array_equal(carried.passes, first._faces.passes >> 1)
    assert np.array_equal(carried.behind, first._faces.behind >> 1)
    assert carried.passes.max() >= 2
    nxt = MapUpdater(first.updated_map(), _config(), faces=carried)
    assert np.array_equal(nxt.carried_faces().passes, carried.passes >> 1)
    # a session of ten seconds moves less than one with the last one's counts behind it
    again = _drive(ref, shapes, _config(), faces=carried, seconds=10.0, seed=2)
    alone = _drive(ref, shapes, _config(), seconds=10.0, seed=2)
    moved = [int((u.updated_map().data != ref.data).sum()) for u in (alone, again)]
    assert moved[1] > moved[0], moved
    # with face_sessions and face_draw_sessions 2, the first session moves nothing, the
    # second what both saw; with face_sessions 2 alone the first session draws, but frees
    # nothing
    two = _config(face_sessions=2, face_draw_sessions=2)
    first2 = _drive(ref, shapes, two, seconds=20.0)
    off = _drive(ref, shapes, _config(move_faces=False), seconds=20.0).updated_map().data
    assert np.array_equal(first2.updated_map().data, off)
    frees_on_two = _drive(ref, shapes, _config(face_sessions=2), seconds=20.0)
    moved = frees_on_two.updated_map().data != off
    assert moved.sum() >= 5 and (frees_on_two.updated_map().data[moved] == OCCUPIED).all()
    second2 = _drive(first2.updated_map(), shapes, two, faces=first2.carried_faces(),
                     seconds=20.0, seed=2)
    moved = second2.updated_map().data != first2.updated_map().data
    near = world.dilate(world.cells_of(OLD) | world.cells_of(NEW), 3)
    assert (moved & near).sum() >= 5 and not np.any(moved & ~near)
    # a session that saw nothing moves nothing: the carried counts alone confirm no cell
    # (they freed 41 cells of a recording's second session before the crossed plane)
    for config, last in ((two, first2), (_config(), first)):
        idle = MapUpdater(last.updated_map(), config, faces=last.carried_faces())
        assert idle.face_cells() > 0
        assert np.array_equal(idle.updated_map().data, last.updated_map().data)
    # with the rule off nothing is kept
    assert MapUpdater(ref, _config(move_faces=False), faces=carried).carried_faces().hits.size \
        == 0


def test_counts_of_another_map_are_refused():
    ref = world.rasterise(world.room_walls())
    wrong = FaceCounts(*(np.zeros((5, 5), np.uint8) for _ in range(3)))
    with pytest.raises(UpdaterError, match=r"face counts' hits do not fit the map"):
        MapUpdater(ref, _config(), faces=wrong)
    grid = OccupancyGrid(np.zeros(ref.shape, np.int8), 0.05)
    bad = FaceCounts(np.zeros(ref.shape, np.uint16), np.zeros(ref.shape, np.uint8),
                     np.zeros(ref.shape, np.uint8))
    with pytest.raises(UpdaterError, match="uint8 expected"):
        MapUpdater(grid, _config(), faces=bad)


def test_a_saved_state_keeps_the_counts(tmp_path):
    ref = world.rasterise(world.room_walls(), hollow=[OLD])
    up = _drive(ref, world.room_walls() + [NEW], _config(), seconds=10.0)
    up.save(tmp_path / "s.npz")
    back = MapUpdater.load(tmp_path / "s.npz")
    assert np.array_equal(back._faces.hits, up._faces.hits)
    assert np.array_equal(back._faces.passes, up._faces.passes)
    assert np.array_equal(back._faces.behind, up._faces.behind)
    assert np.array_equal(back.updated_map().data, up.updated_map().data)
    assert np.array_equal(back._faces.crossed, up._faces.crossed) and up._faces.crossed.any()
    # a state saved before the crossed plane (no face_crossed, nor its checksum) loads, with
    # no crossing of its session yet
    with np.load(tmp_path / "s.npz") as z:
        arrays = {k: z[k] for k in z.files if k != "face_crossed"}
    meta = json.loads(str(arrays["meta"]))
    del meta["checksums"]["face_crossed"]
    arrays["meta"] = np.array(json.dumps(meta))
    np.savez_compressed(tmp_path / "old.npz", **arrays)
    old = MapUpdater.load(tmp_path / "old.npz")
    assert np.array_equal(old._faces.passes, up._faces.passes)
    assert old._faces.crossed.shape == up._faces.crossed.shape and not old._faces.crossed.any()


def test_only_scans_the_pose_check_placed_count_by_default():
    """With face_refined_only (the default), a scan counts when the pose check refined its
    pose: poses taken as given (a recording's, a node's tf) count nothing."""
    from gridmap import PoseVerdict

    ref = world.rasterise(world.room_walls(), hollow=[OLD])
    shapes = world.room_walls() + [NEW]
    cfg = _config(face_refined_only=True)
    given = MapUpdater(ref, cfg)
    placed = MapUpdater(ref, cfg)
    for true, noisy, t in world.Drive(seconds=10.0, seed=1).steps():
        scan = world.full_scan(shapes, true, t)
        given.process(scan, noisy, odometry=true, pose_check=PoseVerdict.accepted)
        placed.process(scan, noisy, odometry=true,
                       pose_check=lambda: PoseVerdict.refined(noisy))
    assert given.carried_faces().hits.size == 0         # nothing counted, nothing held
    assert placed.carried_faces().hits.max() > 0
    assert given.state_bytes() < placed.state_bytes() - 3 * ref.data.size


def test_a_node_s_next_session_carries_the_counts_of_its_frame_only():
    """``onboard.methods.next_session``, as the live nodes' commit uses it: the paper's updater
    and the hybrid carry the counts halved into a map of the same frame; another frame, a
    reset (no last session) or a method without the rule start empty."""
    from onboard.methods import face_cells, make_method, next_session

    ref = world.rasterise(world.room_walls(), hollow=[OLD])
    first = _drive(ref, world.room_walls() + [NEW], _config(), seconds=10.0)
    f = first._faces
    held = int(((f.hits > 0) | (f.passes > 0) | (f.behind > 0)).sum())
    halved = int(((f.hits > 1) | (f.passes > 1) | (f.behind > 1)).sum())
    assert face_cells(first) == held and 0 < halved < held
    nxt = next_session("paper", first, first.updated_map(), _config())
    assert face_cells(nxt) == halved
    assert np.array_equal(nxt.reference_map.data, first.updated_map().data)
    hybrid = next_session("hybrid", first, ref, _config())
    assert face_cells(hybrid) == halved
    assert face_cells(next_session("hybrid", hybrid, ref, _config())) == \
        int(((f.hits > 3) | (f.passes > 3) | (f.behind > 3)).sum())
    other = OccupancyGrid(np.full((50, 60), FREE, np.int8), 0.05)
    assert face_cells(next_session("paper", first, other, _config())) == 0
    assert face_cells(next_session("paper", None, ref, _config())) == 0
    assert face_cells(next_session("fuse", first, ref, _config())) == 0
    assert face_cells(make_method("none", ref, _config())) == 0
