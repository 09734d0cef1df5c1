"""The methods behind the updater's interface (onboard.methods), each driven through the one
robot pipeline in a synthetic room: a box the map has is gone from the world, a box the world
has is missing from the map, and a mapped annex lies outside what the robot can see."""

from __future__ import annotations

import numpy as np
import pytest

from gridmap import FREE, OCCUPIED, UNKNOWN, MapUpdatingError, OccupancyGrid
from onboard.methods import METHODS, MethodError, check_method, make_method
from onboard.pipeline import RobotPipeline
from updater import UpdaterConfig, MapMethod, MapUpdater

import synthetic_room as world

Rect = world.Rect
REMOVED = Rect(4.9125, 5.1125, 6.1125, 5.9125)    # in the map, gone from the world
ADDED = Rect(7.0125, 3.0125, 7.6125, 3.6125)      # in the world, not in the map
ANNEX = (slice(0, 5), slice(60, 140))             # cells below the south wall, never seen


def reference():
    """M: the room with the removed box, without the added one, and a mapped annex outside."""
    grid = world.rasterise(world.room_walls() + [REMOVED])
    data = grid.data.copy()
    data[ANNEX] = FREE
    data[ANNEX[0], 100] = OCCUPIED
    return grid.with_data(data)


@pytest.fixture(scope="module")
def maps():
    """Each method's map after one drive round the room (through the pipeline), and its
    pipeline."""
    shapes = world.room_walls() + [ADDED]
    out = {}
    for name in METHODS:
        pipeline = RobotPipeline(make_method(name, reference(), UpdaterConfig()))
        for true, noisy, t in world.Drive(seconds=40.0, seed=1).steps():
            pipeline.step(world.full_scan(shapes, true, t), world.Pose2D(0.0, 0.0, 0.0),
                          odometry=true, pose=noisy)
        out[name] = (pipeline.updater.updated_map().data, pipeline)
    return out


def _box(rect, data):
    cells = world.cells_of(rect)
    return data[cells]


def test_paper_is_the_updater_itself_and_a_wrong_name_is_refused_with_the_nearest():
    assert type(make_method("paper", reference())) is MapUpdater
    assert check_method("fuse") == "fuse"
    with pytest.raises(MethodError, match=r"unknown method 'fsue' \(did you mean 'fuse'\?\)"):
        make_method("fsue", reference())
    assert issubclass(MethodError, MapUpdatingError)


def test_every_method_sees_the_same_scans_through_the_pipeline(maps):
    counts = {name: p.counts.scans_processed for name, (_, p) in maps.items()}
    assert len(set(counts.values())) == 1 and counts["none"] > 20, counts
    for name, (_, p) in maps.items():
        assert p.updater.state_bytes() >= reference().data.size, name
        assert p.cpu["updater_s"] > 0 or name == "none"


def test_none_changes_nothing(maps):
    data, pipeline = maps["none"]
    assert np.array_equal(data, reference().data)
    assert pipeline.updater.n_changed == 0


def test_remap_forgets_what_the_session_did_not_see(maps):
    data, _ = maps["remap"]
    assert (data[ANNEX] == UNKNOWN).all()                   # mapped before, never seen now
    for kept in ("none", "fuse", "paper"):
        assert (maps[kept][0][ANNEX] != UNKNOWN).all(), kept
    # what it saw it maps: the added box's faces, the removed box's place free
    assert (_box(ADDED, data) == OCCUPIED).mean() > 0.3
    assert (_box(REMOVED, data) == OCCUPIED).sum() == 0


def test_fuse_draws_an_added_box_and_frees_a_removed_one(maps):
    data, _ = maps["fuse"]
    ref = reference().data
    outline = world.cells_of(REMOVED) & (ref == OCCUPIED)
    assert (data[outline] == FREE).mean() > 0.9
    added = _box(ADDED, data)
    assert (added == OCCUPIED).sum() >= 20                  # its faces as the robot sees them
    walls = np.zeros(ref.shape, bool)
    for w in world.room_walls():
        walls |= world.cells_of(w)
    assert (data[walls & (ref == OCCUPIED)] == FREE).mean() < 0.01   # the walls stay


def test_run_refuses_an_unknown_method_before_writing_anything(tmp_path, capsys):
    from mapupdate import main

    out = tmp_path / "run"
    assert main(["run", "--method", "remapp", "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["mapupdate run: error: --method: unknown method 'remapp' (did you mean "
                   "'remap'?) (methods: paper, none, remap, fuse, hybrid)"]
    assert not out.exists()


def test_the_gym_environment_plays_a_session_with_the_method_asked_for(tmp_path):
    gymnasium = pytest.importorskip("gymnasium")
    from scenarios.generator import write_generated
    from onboard.methods import KeepMap

    path = str(write_generated(4, tmp_path / "g.yaml", size=(15, 10), sessions=2))
    with pytest.raises(MethodError, match="did you mean 'fuse'"):
        gymnasium.make("scenarios.gym:WarehouseMapUpdate-v0", scenario=path, method="fusee")
    env = gymnasium.make("scenarios.gym:WarehouseMapUpdate-v0", scenario=path, quick=True,
                         method="none")
    env.reset(seed=1)
    for _ in range(60):
        *_, info = env.step([0.4, 0.0])
    assert isinstance(env.unwrapped.session.updater, KeepMap)
    assert info["scans"] >= 0 and info["updater_changed_cells"] == 0
    assert env.unwrapped.session.pipeline.counts.scans_processed > 0
    env.close()


def test_a_resumed_run_keeps_its_method_and_refuses_another(tmp_path):
    from scenarios.checkpoint import ResumeError
    from scenarios.generator import write_generated
    from scenarios.runner import RunOptions, run_scenario

    path = write_generated(4, tmp_path / "g.yaml", size=(15, 10), sessions=2)
    out = tmp_path / "run"
    run_scenario(path, RunOptions(out=out, sessions=1, quick=True, progress=False,
                                  method="fuse"))
    with pytest.raises(ResumeError, match="method = fuse, not remap"):
        run_scenario(None, RunOptions(out=out, resume=True, progress=False, method="remap"))
    resumed = run_scenario(None, RunOptions(out=out, resume=True, sessions=2, progress=False))
    assert resumed.metrics["method"] == "fuse" and len(resumed.metrics["sessions"]) == 2
    assert "method fuse" in (out / "report.md").read_text()


def _drive(method, reference_map, shapes, seed=1, seconds=40.0):
    """``method`` on ``reference_map`` through the pipeline, one drive round the room; the
    pipeline and the detected-change hit points (x, y) of the scans the updater processed."""
    from updater import BEAM_CHANGE, ScanStatus

    pipeline = RobotPipeline(make_method(method, reference_map, UpdaterConfig()))
    hits = []
    for true, noisy, t in world.Drive(seconds=seconds, seed=seed).steps():
        scan = world.full_scan(shapes, true, t)
        step = pipeline.step(scan, world.Pose2D(0.0, 0.0, 0.0), odometry=true, pose=noisy)
        if step.report.status is ScanStatus.PROCESSED:
            changed = np.zeros(scan.beams, bool)
            changed[step.report.verdicts == BEAM_CHANGE] = True
            valid = np.isfinite(scan.ranges)
            x, y = world.hit_points(scan, noisy)
            hits.append(np.column_stack([x, y])[changed[valid]])
    return pipeline, np.vstack(hits)


def test_hybrid_differs_from_the_paper_only_near_what_the_paper_detected(maps):
    """Where the hybrid's map differs from the paper's, a detected change's hit or a cell the
    paper changed lies within HYBRID_RADIUS; and it changes no cell M has unknown."""
    from onboard.methods import HYBRID_RADIUS

    ref = reference().data
    shapes = world.room_walls() + [ADDED]
    pipeline, hits = _drive("paper", reference(), shapes)
    paper, hybrid = maps["paper"][0], maps["hybrid"][0]
    assert np.array_equal(paper, pipeline.updater.updated_map().data)   # the fixture's drive
    rows, cols = np.nonzero(hybrid != paper)
    assert rows.size > 0
    centres = np.column_stack([(cols + 0.5) * world.RES, (rows + 0.5) * world.RES])
    changed = np.column_stack(np.nonzero(paper != ref))[:, ::-1]
    seeds = np.vstack([hits, (changed + 0.5) * world.RES])
    nearest = np.sqrt(((centres[:, None, :] - seeds[None, :, :]) ** 2).sum(-1)).min(axis=1)
    # one cell of slack: a hit point lies anywhere in its cell
    assert nearest.max() <= HYBRID_RADIUS + world.RES * np.sqrt(0.5) + 1e-9
    assert not np.any((hybrid != paper) & (ref == UNKNOWN))


def test_hybrid_draws_more_of_a_moved_box_than_the_paper_and_nothing_else():
    """A box moved by 0.2 m, less than the pairing distance: the paper draws a third of its new
    outline (tol(r) keeps new-obstacle flags away from the old outline, and the beams on the
    near faces pair with it); the hybrid, whose evidence decides near the detected changes,
    draws most of it, frees as much of the old outline, draws almost nothing false and frees
    no wall."""
    old = Rect(7.0125, 3.0125, 7.6125, 3.6125)
    new = Rect(7.2125, 3.1125, 7.8125, 3.7125)
    ref = world.rasterise(world.room_walls(), hollow=[old])
    truth = world.rasterise(world.room_walls(), hollow=[new]).data
    near_new = world.dilate(truth == OCCUPIED, 1)
    old_face = (ref.data == OCCUPIED) & world.cells_of(old) & ~near_new
    new_face = (truth == OCCUPIED) & (ref.data != OCCUPIED)
    walls = np.zeros(truth.shape, bool)
    for w in world.room_walls():
        walls |= world.cells_of(w)
    out = {}
    for name in ("paper", "hybrid"):
        data = _drive(name, ref, world.room_walls() + [new])[0].updater.updated_map().data
        out[name] = {"old_freed": (data[old_face] == FREE).mean(),
                     "new_drawn": world.dilate(data == OCCUPIED, 1)[new_face].mean(),
                     "false": int(((data == OCCUPIED) & (ref.data != OCCUPIED)
                                   & ~near_new).sum()),
                     "walls_freed": int(((data == FREE) & walls).sum())}
    paper, hybrid = out["paper"], out["hybrid"]
    assert paper["new_drawn"] < 0.45 and hybrid["new_drawn"] >= paper["new_drawn"] + 0.2, out
    assert hybrid["old_freed"] >= paper["old_freed"], out
    assert hybrid["false"] <= 8 and hybrid["walls_freed"] == 0, out


def test_hybrid_maps_asked_for_at_every_scan_end_as_one_asked_for_at_the_end(maps):
    """Its output is worked out when asked and kept until the next processed scan: asking for
    it (and scribbling on the copy it returns) at every scan changes nothing."""
    shapes = world.room_walls() + [ADDED]
    pipeline = RobotPipeline(make_method("hybrid", reference(), UpdaterConfig()))
    for true, noisy, t in world.Drive(seconds=40.0, seed=1).steps():
        pipeline.step(world.full_scan(shapes, true, t), world.Pose2D(0.0, 0.0, 0.0),
                      odometry=true, pose=noisy)
        pipeline.updater.updated_map().data[:] = UNKNOWN
        assert pipeline.updater.n_changed == int((pipeline.updater.current()
                                                  != reference().data).sum())
    assert np.array_equal(pipeline.updater.updated_map().data, maps["hybrid"][0])


@pytest.mark.parametrize("radius", [0.0, -0.1, float("nan"), 6.0, True])
def test_hybrid_refuses_a_radius_out_of_range(radius):
    from onboard.methods import HybridMethod

    with pytest.raises(MethodError, match=r"hybrid: radius must be a number in \(0, 5\] m"):
        HybridMethod(reference(), None, radius=radius)


@pytest.mark.parametrize("name", METHODS)
def test_every_method_implements_the_updater_packages_interface(name):
    grid = OccupancyGrid.empty(20, 10, 0.05)
    method = make_method(name, grid)
    assert isinstance(method, MapMethod)
    assert method.updated_map().shape == grid.shape and method.state_bytes() > 0
