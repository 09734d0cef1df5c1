"""The SENA loop (Malaga, ../shared/data): a map made with ``mapupdate map`` from the SLAM
keyframes, then updated with ``mapupdate update`` from the raw wheel odometry of the same run
and no start given, so the localiser finds the robot over the whole map. Its trajectory (the
scans as the pose check placed them), matched to the keyframes by timestamp, must be within
0.05 m RMSE and 0.20 m at worst; the place did not change between the two, so the update frees
no occupied cell and draws at most 1 % of the occupied count. The same log placed at its
dead-reckoned poses (``--poses recorded``) with the pose check: nearly all the drifted scans
are refused, and nearly nothing freed.

Run with ``-s`` to print the figures.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gridmap import FREE, OCCUPIED, UNKNOWN, load_map
from robotlogs.carmen import read_carmen
from mapupdate import main

DATA = Path(__file__).resolve().parents[2] / "shared/data"
ODOM, KEYFRAMES = DATA / "sena.odom.log", DATA / "sena.keyframes.log"

pytestmark = pytest.mark.skipif(not (ODOM.exists() and KEYFRAMES.exists()),
                                reason=f"the SENA logs are not in {DATA} (see data/README)")


def read_tum(path: Path) -> dict:
    """{time rounded to the microsecond: (x, y)} of a TUM trajectory."""
    rows = np.loadtxt(path, ndmin=2)
    return {round(r[0], 6): (r[1], r[2]) for r in rows}


def run(d: Path, capfd, name: str, *argv) -> str:
    code = main(["update", "--map", str(d / "sena.yaml"), "--log", str(ODOM),
                 "--out", str(d / f"{name}.yaml"), "--no-progress", *map(str, argv)])
    out = capfd.readouterr()
    assert code == 0, out.err
    print(f"\n{out.out}")
    return out.out


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """The map from the keyframes, made once for the module (by the command line)."""
    d = tmp_path_factory.mktemp("sena")
    assert main(["map", "--log", str(KEYFRAMES), "--out", str(d / "sena.yaml"),
                 "--no-progress"]) == 0
    return d


def keyframe_poses() -> dict:
    """{time: (x, y)} of the robot at each keyframe (the keyframes' corrected robot poses)."""
    return {round(r.time, 6): (r.odom_pose.x, r.odom_pose.y)
            for r in read_carmen(KEYFRAMES, strict=True).scans()}


def test_map_from_the_keyframes_is_a_map_server_map(made):
    grid = load_map(made / "sena.yaml")
    c = grid.counts()
    assert grid.resolution == 0.05 and (made / "sena.pgm").exists()
    assert c["occupied"] > 3000 and c["free"] > 100 * c["occupied"] / 2


def test_raw_odometry_no_start_global_localisation_tracks_the_keyframes(made, capfd):
    out = run(made, capfd, "global", "--poses", "localizer", "--trajectory",
              made / "global.tum")
    assert "started over the whole map" in out and "localiser tracking" in out
    est, truth = read_tum(made / "global.tum"), keyframe_poses()
    matched = sorted(set(est) & set(truth))
    errors = np.array([math.dist(est[t], truth[t]) for t in matched])
    rmse = float(np.sqrt(np.mean(errors ** 2)))
    print(f"SENA, global localisation on raw odometry: {len(matched)} of {len(truth)} "
          f"keyframes matched, APE RMSE {rmse:.3f} m, max {errors.max():.3f} m")
    # the trajectory leaves out the scans the pose check refused: the robot profile refuses
    # the localiser's own poses from 0.1 m or 1.5 deg off (35 of the 172 past the gate), and
    # places the others where they fit best
    assert len(matched) >= 0.75 * len(truth)
    assert rmse <= 0.05 and errors.max() <= 0.20
    before, after = load_map(made / "sena.yaml").data, load_map(made / "global.yaml").data
    freed = int(((before == OCCUPIED) & (after == FREE)).sum())
    drawn = int(((before == FREE) & (after == OCCUPIED)).sum())
    grown = int(((before == UNKNOWN) & (after == OCCUPIED)).sum())
    print(f"SENA update: {freed} occupied cells freed, {drawn} free cells drawn "
          f"({(before == OCCUPIED).sum()} occupied in the map); {grown} unknown cells drawn "
          "(surfaces the keyframes' map never saw, grown into)")
    # the map and the log show the same place at the same time: nothing it had may change
    assert freed == 0 and drawn <= 0.01 * (before == OCCUPIED).sum()


def test_dead_reckoned_poses_are_refused_by_the_pose_check(made, capfd):
    checked = run(made, capfd, "recorded_checked", "--poses", "recorded", "--pose-check")
    run(made, capfd, "recorded_plain", "--poses", "recorded", "--no-pose-check")
    before = load_map(made / "sena.yaml").data
    freed = {name: int(((before == OCCUPIED) & (load_map(made / f"{name}.yaml").data == FREE)
                        ).sum()) for name in ("recorded_checked", "recorded_plain")}
    refused = int(checked.split(" refused by the pose check")[0].rsplit(" ", 1)[1])
    processed = int(checked.split(" processed past the gate")[0].rsplit(" ", 1)[1])
    print(f"SENA dead-reckoned: with the check {refused} refused, {processed} processed, "
          f"{freed['recorded_checked']} occupied cells freed; without it "
          f"{freed['recorded_plain']} freed")
    assert refused >= 0.9 * (refused + processed)
    # the robot profile's bounds for a log's poses (0.2 m, 3 deg) let a few dead-reckoned
    # scans through (13 of 199, 2 cells freed): the check takes away all but a hundredth of
    # the damage, and the summary warns that the poses disagree with the map
    assert freed["recorded_plain"] > 50
    assert freed["recorded_checked"] <= 0.01 * freed["recorded_plain"]
    assert "the pose check refused" in checked and "try --poses localizer" in checked
