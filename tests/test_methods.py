"""The methods behind the updater's interface (scenarios.methods), each driven through the one
robot pipeline in a synthetic room: a box the map has is gone from the world, a box the world
has is missing from the map, and a mapped annex lies outside what the robot can see."""

from __future__ import annotations

import numpy as np
import pytest

from gridmap import FREE, MapUpdatingError, OCCUPIED, UNKNOWN
from scenarios.methods import METHODS, MethodError, check_method, make_method
from scenarios.pipeline import RobotPipeline
from updater import MapUpdater

try:
    import synthetic_room as world
except ImportError:  # tests collected as a package
    from tests import synthetic_room as world

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
        pipeline = RobotPipeline(make_method(name, reference()))
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
    from scenarios.cli import main

    out = tmp_path / "run"
    assert main(["run", "--method", "remapp", "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["mapupdate run: error: --method: unknown method 'remapp' (did you mean "
                   "'remap'?) (methods: paper, none, remap, fuse)"]
    assert not out.exists()


def test_the_gym_environment_plays_a_session_with_the_method_asked_for(tmp_path):
    gymnasium = pytest.importorskip("gymnasium")
    from scenarios.generator import write_generated
    from scenarios.methods import KeepMap

    path = str(write_generated(4, tmp_path / "g.yaml", size=(15, 10), sessions=2))
    with pytest.raises(MethodError, match="did you mean 'fuse'"):
        gymnasium.make("WarehouseMapUpdate-v0", scenario=path, method="fusee")
    env = gymnasium.make("WarehouseMapUpdate-v0", scenario=path, quick=True, method="none")
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
