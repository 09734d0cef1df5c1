"""``mapupdate map``: a first map from a log with corrected poses, by the log-odds mapping that
builds M1 in the simulator; its frame, the poses it uses, and its refusals."""

from __future__ import annotations

import numpy as np
import pytest

from gridmap import load_map
from gridmap.mapping import LogOddsMapper
from robotlogs import LogError
from robotlogs.rosbag import write_bag
from mapupdate import main
from onboard.logmap import map_from_log

import test_logs_replay as room


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    d = tmp_path_factory.mktemp("maplogs")
    steps = room.session()
    write_bag(d / "s.bag", room.bag_records(steps), "ros1")
    write_bag(d / "raw.bag", room.bag_records(steps, map_odom_tf=False, amcl=False), "ros1")
    return d, steps


def test_map_of_a_bag_is_the_log_odds_map_of_its_scans_at_the_recorded_poses(logs, capfd):
    d, steps = logs
    assert main(["map", "--log", str(d / "s.bag"), "--out", str(d / "m.yaml"),
                 "--no-progress"]) == 0
    out = capfd.readouterr().out
    assert out.startswith(f"wrote {d / 'm.yaml'}: ") and f"{len(steps)} of {len(steps)} scans " \
        "mapped (poses: recorded)" in out
    made = load_map(d / "m.yaml")
    mapper = LogOddsMapper(made)                  # the same frame, the same increments
    for t, true, odom, scan in steps:
        mapper.add_scan(scan, true.compose(odom.inverse()).compose(odom).compose(room.MOUNT))
    differ = int((mapper.to_grid().data != made.data).sum())
    assert differ <= 3                            # rounding of the recorded poses in the bag
    # the frame holds every hit with a metre to spare, its corners on whole metres
    x0, y0, x1, y1 = made.extent()
    assert (x0, y0) == (-2.0, -2.0) and x1 >= 9.0 and y1 >= 7.0
    assert made.counts()["occupied"] > 400


def test_resolution_and_the_truth(logs):
    d, _ = logs
    s = map_from_log(d / "s.bag", d / "coarse.yaml", resolution=0.1, pose_source="truth",
                     progress=False)
    assert s["resolution"] == 0.1 and load_map(d / "coarse.yaml").resolution == 0.1


@pytest.mark.parametrize("kwargs, says", [
    ({"resolution": 0.0}, "--resolution must be a number of metres in"),
    ({"resolution": float("nan")}, "--resolution must be a number of metres in"),
    ({"resolution": 1e-6}, "--resolution must be a number of metres in"),
    ({"pose_source": "localizer"}, "the map's poses must be one of recorded, truth"),
])
def test_bad_arguments_are_refused_before_any_work(logs, kwargs, says):
    d, _ = logs
    with pytest.raises(LogError, match=says):
        map_from_log(d / "s.bag", d / "x.yaml", progress=False, **kwargs)
    assert not (d / "x.yaml").exists()


def test_a_log_without_corrected_poses_cannot_make_a_map(logs):
    d, _ = logs
    with pytest.raises(LogError, match="no corrected poses to map with"):
        map_from_log(d / "raw.bag", d / "x.yaml", progress=False)


def test_the_map_never_overwrites_the_log(tmp_path):
    log = tmp_path / "run.pgm"
    log.write_text("FLASER 2 1.0 1.0 0 0 0 0 0 0 1.0 h 0\n")
    before = log.read_bytes()
    with pytest.raises(LogError, match="would overwrite the log"):
        map_from_log(log, tmp_path / "run.yaml", progress=False)
    assert log.read_bytes() == before


def test_a_map_too_large_for_memory_is_refused(tmp_path):
    # two lines 50 km apart: 1e6 x 1 cells at 5 cm would be fine, 1e6 x 1e6 is not
    lines = ["FLASER 2 1.0 1.0 0 0 0 0 0 0 1.0 h 0",
             "FLASER 2 1.0 1.0 50000 50000 0 50000 50000 0 2.0 h 0"]
    (tmp_path / "far.log").write_text("\n".join(lines) + "\n")
    with pytest.raises(LogError, match=r"far.log: the scans span .* give a coarser "
                                       r"--resolution"):
        map_from_log(tmp_path / "far.log", tmp_path / "far.yaml", progress=False)
    assert np.all([not p.name.startswith("far.") or p.suffix == ".log"
                   for p in tmp_path.iterdir()])


def test_a_map_the_loader_would_refuse_is_not_written(tmp_path, capsys):
    # 500 m x 480 m at 5 cm: 96 M cells, over the 64 M a map file may have, under 200 M
    lines = ["FLASER 2 1.0 1.0 0 0 0 0 0 0 1.0 h 0",
             "FLASER 2 1.0 1.0 497 477 0 497 477 0 2.0 h 0"]
    (tmp_path / "wide.log").write_text("\n".join(lines) + "\n")
    assert main(["map", "--log", str(tmp_path / "wide.log"), "--out",
                 str(tmp_path / "wide.yaml"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "more than 64000000 cells; give a coarser --resolution" in err[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["wide.log"]
