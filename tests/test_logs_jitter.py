"""Jittery recorded poses: a synthetic 17 x 11 m hall (tests/synthetic_hall.py) recorded as a ROS
bag with smooth wheel odometry and a localisation ``map -> odom`` whose poses jitter by 2 cm and
0.5 deg (std) at every scan, two objects removed, one moved, two added and three people
walking. ``mapupdate update`` of the hall's old map, with its defaults, must free the removed
objects whole, draw the added ones (at least 95 % of the outline cells its scans see often
enough, one cell of slack as in docs/evaluation.md), draw no false occupied cell and free no wall
cell, with and without the pose check, and the check must refine the scans, not refuse them.

By default ``update`` smooths a localisation that jitters against the odometry over 2 s
(``localization.smoothing``): the runs draw 0.984-1.000 of the outline over seeds 0-4, with and
without the check. The check's refinement places a scan about 1.5 cm from the truth here (the
fit pulls the hits of the hall's faces, which all lie a quarter of a cell into their cells, to
the cells' centres), the smoothed poses are 0.5 cm from it, so on seeds 0, 3 and 4 the run with
the check misses 1-2 cells (of 126) of a face seen only at grazing angles that the run without
it draws; the last test bounds that. With the poses as recorded (``--smooth-poses 0``) the run
without the check draws 0.79-0.91 of the outline, and the check keeps every cell of it while it
refuses about a third of the scans (the best pose nearby lies 0.75 deg or more away). Run with
``-s`` to print the figures.
"""

from __future__ import annotations

import numpy as np
import pytest

from gridmap import FREE, OCCUPIED, load_map, save_map
from robotlogs.rosbag import write_bag
from localization.confidence import PoseCheckConfig
from onboard.replay import LogSource, Outputs, Placement, update_from_log

import synthetic_hall as hall

SEEDS = [0, 1, 2, pytest.param(3, marks=pytest.mark.slow), pytest.param(4, marks=pytest.mark.slow)]
DEFAULT, AS_RECORDED = None, 0.0      # smoothing window: update's default, or none


def grow(mask: np.ndarray) -> np.ndarray:
    """``mask`` and its 8-neighbours: one cell of slack."""
    p = np.pad(mask, 1)
    out = mask.copy()
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            out |= p[1 + dr:p.shape[0] - 1 + dr, 1 + dc:p.shape[1] - 1 + dc]
    return out


@pytest.fixture(scope="module")
def halls(tmp_path_factory):
    """The recorded hall of each seed, built when first asked; and the runs made on it."""
    return {"dir": tmp_path_factory.mktemp("halls"), "seeds": {}, "runs": {}}


def hall_log(halls, seed: int) -> dict:
    if seed not in halls["seeds"]:
        d = halls["dir"] / f"seed{seed}"
        d.mkdir()
        steps = hall.record(seed=seed)
        write_bag(d / "hall.bag", hall.bag_records(steps), "ros1")
        reference = hall.rasterise(hall.before())
        save_map(reference, d / "hall.yaml")
        gone = np.zeros(reference.shape, bool)
        for shape in list(hall.REMOVED.values()) + [a for a, _ in hall.MOVED.values()]:
            gone |= hall.outline(shape)
        new = np.zeros(reference.shape, bool)
        for shape in list(hall.ADDED.values()) + [b for _, b in hall.MOVED.values()]:
            new |= hall.outline(shape)
        now = hall.rasterise(hall.after())
        halls["seeds"][seed] = {
            "dir": d, "reference": reference, "gone": gone, "seen": hall.visible(steps, new),
            "near_truth": grow(now.data == OCCUPIED),
            "walls": (reference.data == OCCUPIED) & (now.data == OCCUPIED)}
    return halls["seeds"][seed]


def run(halls, seed: int, check: bool, smooth: float | None, check_profile: str = "robot"
        ) -> dict:
    """``update``'s defaults (the robot profile), the pose check on or off, its configuration
    the ``check_profile``'s (the paper's refines the scans it trusts, the robot's keeps
    their poses)."""
    key = (seed, check, smooth, check_profile)
    if key not in halls["runs"]:
        h = hall_log(halls, seed)
        out = h["dir"] / f"out_{check}_{smooth}_{check_profile}.yaml"
        window = {} if smooth is None else {"smooth_window": smooth}
        config = PoseCheckConfig.profile(check_profile)
        s = update_from_log(h["dir"] / "hall.yaml", LogSource(h["dir"] / "hall.bag"),
                            Outputs(out), Placement(pose_check=check, pose_check_config=config,
                                                    **window))
        cells = load_map(out).data
        ref = h["reference"].data
        drawn = grow(cells == OCCUPIED) & h["seen"]
        figures = {
            "removed_freed": float((cells[h["gone"]] == FREE).mean()),
            "added_drawn": float(drawn.sum() / h["seen"].sum()), "drawn": drawn,
            "outline": int(h["seen"].sum()),
            "false_occupied": int(((cells == OCCUPIED) & (ref != OCCUPIED)
                                   & ~h["near_truth"]).sum()),
            "walls_freed": int((h["walls"] & (cells == FREE)).sum()),
            "refused": s["scans_refused_by_pose_check"], "processed": s["scans_processed"],
            "smoothed": s["smoothing"]["scans_smoothed"]}
        print(f"\nhall seed {seed}, pose check {'on (' + check_profile + ')' if check else 'off'}, smoothing "
              f"{'default' if smooth is None else smooth}: "
              + ", ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}"
                          for k, v in figures.items() if k != "drawn"))
        halls["runs"][key] = figures
    return halls["runs"][key]


@pytest.mark.parametrize("check", [False, True], ids=["without check", "with check"])
@pytest.mark.parametrize("seed", SEEDS)
def test_jittery_poses_free_the_removed_draw_the_added_and_nothing_else(halls, seed, check):
    f = run(halls, seed, check, DEFAULT)
    assert f["smoothed"] > 100                       # the jitter was seen and smoothed
    assert f["removed_freed"] == 1.0
    assert f["added_drawn"] >= 0.95
    assert f["false_occupied"] == 0 and f["walls_freed"] == 0
    assert f["refused"] <= 0.05 * (f["processed"] + f["refused"])   # refined, not refused


@pytest.mark.parametrize("seed", SEEDS)
def test_the_check_keeps_nearly_all_the_run_without_it_draws(halls, seed):
    off, on = run(halls, seed, False, DEFAULT), run(halls, seed, True, DEFAULT)
    assert int((off["drawn"] & ~on["drawn"]).sum()) <= 2          # measured 0-2 of 126


@pytest.mark.parametrize("seed", SEEDS)
def test_poses_as_recorded_the_check_keeps_all_the_run_without_it_draws(halls, seed):
    """Without smoothing the jitter reaches the updater: 0.5 deg moves a hit 9 cm at 10 m, and
    a face no longer collects 7 changed flags of 10 in one cell. With the paper's rules alone
    the added objects were then drawn only in part without the check; the robot's gate and
    unanimous rule draw them whole, and some false cells with them. The check refines the
    scans it trusts and refuses about a third, keeps every cell the run without it draws and
    draws 0.95 or more of the outline, nothing false."""
    off, on = run(halls, seed, False, AS_RECORDED), run(halls, seed, True, AS_RECORDED, "paper")
    assert off["smoothed"] == on["smoothed"] == 0
    assert on["removed_freed"] == 1.0 and on["added_drawn"] >= 0.95
    assert on["false_occupied"] == 0 and on["walls_freed"] == 0
    assert not np.any(off["drawn"] & ~on["drawn"])
    # without the check the jitter reaches the updater: with the robot's gate (a view every
    # 0.2 m) and its unanimous rule, 0-6 wall cells freed and 19-40 false cells over seeds 0-4,
    # none with the check
    assert off["added_drawn"] >= 0.95 and off["walls_freed"] <= 10
    assert off["false_occupied"] + off["walls_freed"] > on["false_occupied"] + on["walls_freed"]


@pytest.mark.parametrize("seed", SEEDS)
def test_poses_as_recorded_the_robot_profiles_check_frees_no_wall(halls, seed):
    """The robot profile's check keeps the poses it trusts (its refinement drew fewer added
    objects on real buildings' corrected poses) and refuses only a pose a fifth of a metre or
    3 deg off: with the jitter as recorded it frees no wall, as the paper's refining check,
    and draws the false cells the run without a check draws (the default smoothing draws
    none: the tests above)."""
    off, robot = run(halls, seed, False, AS_RECORDED), run(halls, seed, True, AS_RECORDED)
    assert robot["walls_freed"] == 0 and robot["removed_freed"] == 1.0
    assert robot["added_drawn"] >= 0.95
    assert robot["false_occupied"] <= off["false_occupied"] + 5
