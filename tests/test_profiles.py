"""Two profiles, one home: every entry point starts from the robot profile unless told
otherwise, a configuration file lays its keys over the profile one by one, and what runs is
said. The profiles' table in the docs is the code's."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from gridmap import load_map, save_map
from gridmap.config import PROFILES
from localization import LocalizerConfig, MonteCarloLocalizer
from localization.confidence import PoseCheckConfig
from mapupdate import main
from onboard.robot_config import (CLASSES, POSE_CHECK_ON, load_robot_config,
                                profile_table_markdown)
from updater import MapUpdater, UpdaterConfig
from updater import config as updater_config

import synthetic_room as world

ROOT = Path(__file__).resolve().parents[1]
BOX = world.Rect(5.2, 5.2, 5.8, 5.8)      # in the map, gone from the room


def test_the_docs_table_of_the_profiles_is_the_codes():
    doc = (ROOT / "docs" / "configuration.md").read_text()
    assert profile_table_markdown() in doc


def test_the_robot_profile_differs_from_the_paper_exactly_where_its_table_says():
    paper, robot = UpdaterConfig.profile("paper"), UpdaterConfig.profile("robot")
    assert paper == UpdaterConfig()                     # the paper: the class's defaults
    differ = {k for k, v in robot.to_dict().items() if paper.to_dict()[k] != v}
    assert differ == set(updater_config.ROBOT_PROFILE)
    for name, cls in CLASSES.items():
        assert cls.profile("paper") == cls()
    assert LocalizerConfig.profile("robot").update_min_d == 0.1
    assert PoseCheckConfig.profile("robot").known_ends_only
    assert {p: POSE_CHECK_ON[p][0] for p in PROFILES} == {"paper": False, "robot": True}


def test_the_library_starts_from_the_robot_profile(tmp_path):
    grid = world.rasterise(world.room_walls())
    assert MapUpdater(grid).config == UpdaterConfig.profile("robot")
    assert MapUpdater(grid, profile="paper").config == UpdaterConfig()
    assert MonteCarloLocalizer(grid).config == LocalizerConfig.profile("robot")
    assert MonteCarloLocalizer(grid, profile="paper").config == LocalizerConfig()
    with pytest.raises(ValueError, match=r"unknown profile 'papr' \(did you mean 'paper'\?\)"):
        MapUpdater(grid, profile="papr")


def test_a_one_key_file_keeps_every_other_key_of_the_profile():
    """The file of the report: `updater: {threshold: 8}` keeps all of the robot's rules."""
    for profile in PROFILES:
        config = load_robot_config({"updater": {"threshold": 8}}, profile=profile)
        assert config.updater == UpdaterConfig.profile(profile, {"threshold": 8})
        assert config.differences() == [f"updater.threshold: 8 (profile {profile}: 7)"]
    robot = load_robot_config({"updater": {"threshold": 8}}).updater
    assert all(getattr(robot, k) == v for k, (v, _) in updater_config.ROBOT_PROFILE.items())


# --- update: the same map with a key at its profile's value -----------------------------------
@pytest.fixture(scope="module")
def room(tmp_path_factory):
    d = tmp_path_factory.mktemp("profiles")
    save_map(world.rasterise(world.room_walls() + [BOX]), d / "map.yaml")
    poses = [true for true, _, _ in world.Drive(seconds=30.0, rate=10.0).steps()]
    world.carmen_log(d / "circle.log", poses, [0.1 * k for k in range(len(poses))])
    return d


def update(room, capsys, out, *more) -> tuple[np.ndarray, str]:
    assert main(["update", "--map", str(room / "map.yaml"), "--log", str(room / "circle.log"),
                 "--out", str(out), "--no-progress", *map(str, more)]) == 0
    return load_map(out).data, capsys.readouterr().out


@pytest.mark.parametrize("profile", PROFILES)
def test_update_with_a_key_at_its_profile_value_gives_the_same_map(room, capsys, profile):
    cfg = room / f"{profile}.yaml"
    cfg.write_text(yaml.safe_dump({"updater": {"threshold": 7}, "pose_check": {"cap": 0.2}}))
    plain, said = update(room, capsys, room / f"{profile}-plain.yaml", "--profile", profile)
    keyed, said_keyed = update(room, capsys, room / f"{profile}-keyed.yaml", "--profile",
                               profile, "--config", cfg)
    assert (plain != load_map(room / "map.yaml").data).sum() > 20    # the box went
    assert np.array_equal(plain, keyed)
    assert f"profile {profile}" in said and "configuration over" not in said_keyed


def test_update_defaults_to_the_robot_profile_and_names_what_differs(room, capsys):
    cfg = room / "eight.yaml"
    cfg.write_text(yaml.safe_dump({"updater": {"threshold": 8}}))
    default, said = update(room, capsys, room / "default.yaml")
    robot, _ = update(room, capsys, room / "robot.yaml", "--profile", "robot")
    _, said_paper = update(room, capsys, room / "paper.yaml", "--profile", "paper")
    _, said_eight = update(room, capsys, room / "eight-out.yaml", "--config", cfg)
    assert np.array_equal(default, robot)
    assert "profile robot" in said.splitlines()[0] and "profile paper" in said_paper
    # the robot profile's gate keeps a view every 0.2 m, the authors' every 0.4 m
    processed = [int(s.split(" processed past the gate")[0].split()[-1])
                 for s in (said, said_paper)]
    assert processed[0] > processed[1], processed
    assert "configuration over the robot profile: updater.threshold: 8 (profile robot: 7)" \
        in said_eight


def test_a_misspelt_profile_is_one_line_before_anything_is_read(room, capsys):
    out = room / "never.yaml"
    assert main(["update", "--map", str(room / "map.yaml"), "--log", str(room / "circle.log"),
                 "--out", str(out), "--profile", "robt", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["mapupdate update: error: --profile: unknown profile 'robt' (did you mean "
                   "'robot'?) (profiles: paper, robot)"]
    assert not out.exists()


# --- the testbed's entry points ----------------------------------------------------------------
def test_run_the_fleet_the_gym_env_and_sweeps_start_from_the_robot_profile(tmp_path):
    from scenarios.fleet import FleetOptions
    from scenarios.options import RunOptions
    from scenarios.runner import resolve_profile
    from studies.sweep import check_spec, plan
    from tiny_room import tiny_room

    room = tiny_room()
    opts = resolve_profile(room, RunOptions())
    assert opts.profile == "robot" and opts.pose_check is True
    assert opts.updater_config == UpdaterConfig.profile("robot")
    assert opts.localizer_config.update_min_d == 0.1                  # the profile's ...
    assert opts.localizer_config.alpha1 == room.robot.odometry_noise[0]   # ... robot's alphas
    paper = resolve_profile(room, RunOptions(profile="paper", localizer_config={"z_hit": 0.7}))
    assert paper.pose_check is False and paper.updater_config == UpdaterConfig()
    assert paper.localizer_config.z_hit == 0.7 and paper.localizer_config.update_min_d == 0.25
    assert FleetOptions().profile == "robot"
    spec = check_spec({"scenarios": ["aws_small_warehouse"], "profile": ["paper", "robot"],
                       "config": {"updater": {"threshold": 8}}}, "spec", tmp_path)
    runs = plan(spec, tmp_path)
    assert [r.config for r in runs] == [{"updater": {"threshold": 8}, "profile": p}
                                        for p in ("paper", "robot")]
    assert [r.config for r in plan(check_spec({"scenarios": ["aws_small_warehouse"]}, "spec",
                                              tmp_path), tmp_path)] == [{}]


def test_the_main_jobs_report_names_the_profile_and_compares_the_papers(tmp_path):
    from tiny_room import write_tiny_room

    scenario = write_tiny_room(tmp_path / "room.yaml")
    assert main(["run", str(scenario), "--out", str(tmp_path / "run"), "--no-progress"]) == 0
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert metrics["profile"] == "robot" and metrics["pose_check"] is True
    session = metrics["sessions"][1]
    assert session["comparison"]["profile"] == "paper"
    assert set(session["comparison"]["change_detection"]) >= {"precision", "recall"}
    report = (tmp_path / "run" / "report.md").read_text()
    assert "Profile `robot`" in report and "| M(i), paper profile |" in report
    assert "| W2 | paper |" in report and "| W2 | robot |" in report


def test_the_robot_check_places_its_own_localisers_poses_and_keeps_a_logs():
    """The robot profile's check places a scan of the project's own localiser where it fits
    (a few centimetres off: corrected; 0.15 m off: refused), and takes a log's pose as given
    (0.15 m off: kept, not moved; past 0.2 m: refused)."""
    from gridmap import Pose2D, Verdict
    from localization.confidence import PoseCheck

    walls = world.room_walls() + [world.Rect(2.0125, 2.0125, 3.2125, 2.8125)]
    ref = world.rasterise(walls)
    true, mount = Pose2D(5.5, 5.5, 0.3), Pose2D(0.0, 0.0, 0.0)
    scan = world.full_scan(walls, true, 0.0)
    robot = PoseCheckConfig.profile("robot")
    own, given = robot.for_poses(own_localizer=True), robot.for_poses(own_localizer=False)
    assert own.refine and not given.refine
    # the paper profile refines every pose, at its own bounds
    assert PoseCheckConfig.profile("paper").for_poses(False) == PoseCheckConfig.profile("paper")

    def verdict(config, dx):
        return PoseCheck(ref, config).verdict(scan, Pose2D(true.x + dx, true.y, true.theta),
                                              mount)

    near = verdict(own, 0.04)
    assert near.verdict is Verdict.REFINED
    assert abs(near.sensor_pose.x - true.x) < 0.015 and abs(near.sensor_pose.y - true.y) < 0.015
    assert verdict(own, 0.15).verdict is Verdict.REFUSED
    assert verdict(given, 0.04).verdict is Verdict.ACCEPTED
    assert verdict(given, 0.15).verdict is Verdict.ACCEPTED
    assert verdict(given, 0.3).verdict is Verdict.REFUSED
