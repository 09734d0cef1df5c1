"""The robot software's configuration file (``--config``, the gym env's ``config=``, a run's
checkpoint): every unknown section or key refused in one line naming the nearest valid one,
before anything runs or is written; a valid file is what the components get."""

import json

import pytest
import yaml

import mapupdate.testbed_commands
import scenarios.runner
from localization import LocalizerConfig
from localization.confidence import PoseCheckConfig
from mapupdate import main
from onboard.robot_config import ConfigError, RobotConfig, load_robot_config
from tiny_room import tiny_room, write_tiny_room
from updater import UpdaterConfig

MISSPELT = [
    ({"updater": {"treshold": 9}}, "unknown key 'treshold' in section 'updater'", "threshold"),
    ({"localizer": {"max_particle": 900}}, "unknown key 'max_particle' in section 'localizer'",
     "max_particles"),
    ({"pose_check": {"slack_cell": 1}}, "unknown key 'slack_cell' in section 'pose_check'",
     "slack_cells"),
    ({"updatr": {"threshold": 9}}, "unknown section 'updatr'", "updater"),
    ({"posecheck": {}}, "unknown section 'posecheck'", "pose_check"),
]
VALID = {"updater": {"threshold": 9},
         "localizer": {"max_particles": 900, "alpha1": 0.05, "alpha2": 0.01, "alpha3": 0.05,
                       "alpha4": 0.01},
         "pose_check": {"slack_cells": 1, "max_gain": 0.02}}


def write_yaml(path, doc):
    path.write_text(yaml.safe_dump(doc))
    return path


def one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


# --- the loader --------------------------------------------------------------------------------
def test_a_valid_file_lays_its_keys_over_the_robot_profile(tmp_path):
    config = load_robot_config(write_yaml(tmp_path / "robot.yaml", VALID))
    assert config.profile == "robot"
    assert config.updater == UpdaterConfig.profile("robot", {"threshold": 9})
    assert config.updater.unanimous_min == 3 and config.updater.free_with_neighbours
    assert config.localizer == LocalizerConfig(max_particles=900, alpha1=0.05, alpha2=0.01,
                                               alpha3=0.05, alpha4=0.01, update_min_d=0.1)
    assert config.pose_check == PoseCheckConfig.profile("robot", {"slack_cells": 1,
                                                                  "max_gain": 0.02})
    assert load_robot_config(config.to_dict()) == config
    paper = load_robot_config(VALID, profile="paper")
    assert paper.updater == UpdaterConfig(threshold=9)
    assert paper.pose_check == PoseCheckConfig(slack_cells=1, max_gain=0.02)
    assert not paper.use_pose_check and config.use_pose_check


def test_sections_left_out_or_empty_are_the_profiles(tmp_path):
    path = tmp_path / "robot.yaml"
    path.write_text("updater:\nlocalizer: {}\npose_check:\n  cap: 1\n")
    config = load_robot_config(path)
    assert (config.updater, config.localizer) == (UpdaterConfig.profile("robot"),
                                                  LocalizerConfig.profile("robot"))
    assert config.pose_check == PoseCheckConfig.profile("robot", {"cap": 1.0})
    assert config.differences() == ["pose_check.cap: 1.0 (profile robot: 0.2)"]
    path.write_text("")
    assert load_robot_config(path) == RobotConfig() == load_robot_config(None)
    assert RobotConfig().differences() == []


def test_the_file_may_name_its_profile_and_the_command_line_wins(tmp_path):
    path = write_yaml(tmp_path / "robot.yaml", {"profile": "paper", "updater": {"threshold": 8}})
    assert load_robot_config(path).updater == UpdaterConfig(threshold=8)
    assert load_robot_config(path, profile="robot").updater == \
        UpdaterConfig.profile("robot", {"threshold": 8})
    with pytest.raises(ConfigError, match=r"robot.yaml: profile: unknown profile 'papr' "
                                          r"\(did you mean 'paper'\?\)"):
        load_robot_config({"profile": "papr"}, source="robot.yaml")
    with pytest.raises(ConfigError, match=r"--profile: unknown profile 'robt'"):
        load_robot_config(None, profile="robt")


@pytest.mark.parametrize("doc, message, near", MISSPELT)
def test_an_unknown_section_or_key_names_the_nearest_valid_one(doc, message, near):
    with pytest.raises(ConfigError) as e:
        load_robot_config(doc, source="robot.yaml")
    assert str(e.value) == f"robot.yaml: {message} (did you mean '{near}'?)"


def test_a_flat_updater_file_is_told_where_its_keys_go(tmp_path):
    with pytest.raises(ConfigError, match=r"unknown section 'threshold' \('threshold' is a key "
                                          r"of section 'updater': put it under 'updater:'\)"):
        load_robot_config(write_yaml(tmp_path / "old.yaml", {"threshold": 9}))


def test_bad_values_and_shapes_name_the_file_and_the_section(tmp_path):
    from updater import UpdaterError

    with pytest.raises(UpdaterError, match=r"robot.yaml, section 'updater': config key "
                                           r"'threshold' \(12\) exceeds 'buffer_size'"):
        load_robot_config({"updater": {"threshold": 12}}, source="robot.yaml")
    with pytest.raises(ConfigError, match="section 'localizer' must be a mapping of keys, got list"):
        load_robot_config({"localizer": [1, 2]})
    with pytest.raises(ConfigError, match="expected a mapping of sections"):
        load_robot_config(write_yaml(tmp_path / "list.yaml", [1, 2]))
    with pytest.raises(ConfigError, match="configuration file not found"):
        load_robot_config(tmp_path / "missing.yaml")
    (tmp_path / "broken.yaml").write_text("updater: [\n")
    with pytest.raises(ConfigError, match="broken.yaml: not valid YAML"):
        load_robot_config(tmp_path / "broken.yaml")


def test_the_pose_check_config_loads_like_the_others(tmp_path):
    from localization import LocalizationError

    c = PoseCheckConfig(slack_cells=1, refine=False)
    assert PoseCheckConfig.from_dict(c.to_dict()) == c
    assert PoseCheckConfig.from_dict({"cap": 1}).cap == 1.0          # YAML's 1 for 1.0
    path = write_yaml(tmp_path / "check.yaml", {"pose_check": {"max_beams": 90}})
    assert PoseCheckConfig.from_yaml(path) == PoseCheckConfig(max_beams=90)
    with pytest.raises(LocalizationError, match="unknown key 'retry_intervall'.*did you mean "
                                                "'retry_interval'"):
        PoseCheckConfig.from_dict({"retry_intervall": 1.0})
    assert LocalizerConfig.from_dict(LocalizerConfig(z_hit=0.7).to_dict()) == \
        LocalizerConfig(z_hit=0.7)


# --- the command line --------------------------------------------------------------------------
@pytest.mark.parametrize("doc, message, near", MISSPELT)
def test_run_refuses_a_misspelt_file_before_writing_anything(tmp_path, capsys, doc, message,
                                                              near):
    cfg = write_yaml(tmp_path / "cfg.yaml", doc)
    out, rrd = tmp_path / "run", tmp_path / "run.rrd"
    assert main(["run", "--config", str(cfg), "--out", str(out), "--no-progress", "--quick",
                 "--rerun", str(rrd)]) == 2
    line = one_line(capsys.readouterr().err)
    assert line == f"mapupdate run: error: {cfg}: {message} (did you mean '{near}'?)"
    assert not out.exists() and not rrd.exists()


@pytest.mark.parametrize("doc, message, near", MISSPELT)
def test_update_refuses_a_misspelt_file_before_reading_the_log(tmp_path, capsys, doc, message,
                                                               near):
    cfg = write_yaml(tmp_path / "cfg.yaml", doc)
    out = tmp_path / "updated.yaml"
    # neither the map nor the log exists: the configuration is refused first
    assert main(["update", "--map", str(tmp_path / "map.yaml"), "--log", str(tmp_path / "log"),
                 "--out", str(out), "--config", str(cfg), "--no-progress"]) == 2
    line = one_line(capsys.readouterr().err)
    assert line == f"mapupdate update: error: {cfg}: {message} (did you mean '{near}'?)"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cfg.yaml"]


def test_update_hands_the_sections_to_the_replay(tmp_path, monkeypatch):
    import onboard.replay

    seen = {}

    def fake_update(map_path, log, outputs, placement, **kw):
        seen.update(kw, placement=placement)
        return {"scans_processed": 0, "scans": 0, "scans_dropped_as_lost": 0,
                "scans_refused_by_pose_check": 0, "cells_freed": 0, "cells_occupied": 0,
                "pose_source": "recorded"}

    monkeypatch.setattr(onboard.replay, "update_from_log", fake_update)
    cfg = write_yaml(tmp_path / "cfg.yaml", VALID)
    assert main(["update", "--map", "m.yaml", "--log", "l.log", "--out", "o.yaml", "--config",
                 str(cfg), "--pose-check", "--no-progress"]) == 0
    assert seen["updater_config"] == UpdaterConfig.profile("robot", {"threshold": 9})
    placement = seen["placement"]
    assert placement.localizer_config.max_particles == 900
    assert placement.pose_check_config == PoseCheckConfig.profile(
        "robot", {"slack_cells": 1, "max_gain": 0.02})
    assert placement.pose_check is True and placement.profile == "robot"


@pytest.mark.parametrize("flag, on", [([], None), (["--pose-check"], True),
                                      (["--no-pose-check"], False)])
def test_run_keeps_the_pose_check_switch_beside_the_file(tmp_path, monkeypatch, flag, on):
    from types import SimpleNamespace

    seen = []
    monkeypatch.setattr(mapupdate.testbed_commands, "run_scenario", lambda scenario, opts: (
        seen.append(opts), SimpleNamespace(out_dir=tmp_path))[1])
    cfg = write_yaml(tmp_path / "cfg.yaml", {"pose_check": {"slack_cells": 1}})
    assert main(["run", "--config", str(cfg), "--no-progress", *flag]) == 0
    (opts,) = seen
    assert opts.pose_check is on        # None: the profile's, which the runner applies
    assert opts.pose_check_config == PoseCheckConfig.profile("robot", {"slack_cells": 1})
    assert (opts.updater_config, opts.localizer_config) == (None, None)


@pytest.fixture(scope="module")
def configured_run(tmp_path_factory):
    """The tiny room played with VALID; the configurations its update session was given."""
    folder = tmp_path_factory.mktemp("configured")
    scenario = write_tiny_room(folder / "room.yaml")
    cfg = write_yaml(folder / "cfg.yaml", VALID)
    given = []

    class Recording(scenarios.runner.UpdateSession):
        def __init__(self, *args, **kw):
            super().__init__(*args, **kw)
            given.append((self.updater.config, self.localizer.config,
                          self.pipeline.pose_check.config))

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(scenarios.runner, "UpdateSession", Recording)
        assert main(["run", str(scenario), "--config", str(cfg), "--out", str(folder / "run"),
                     "--no-progress"]) == 0
    return folder / "run", given


def test_run_gives_the_sessions_the_configured_components(configured_run):
    out, given = configured_run
    (updater, localizer, pose_check), = given
    assert updater.threshold == 9 and updater == UpdaterConfig.profile("robot", {"threshold": 9})
    assert localizer.max_particles == 900 and localizer.alpha1 == 0.05
    assert localizer.update_min_d == 0.1            # the robot profile's, under the keys
    # as the check places the project's own localiser's scans
    assert pose_check == PoseCheckConfig.profile(
        "robot", {"slack_cells": 1, "max_gain": 0.02}).for_poses(own_localizer=True)
    recorded = json.loads((out / "state" / "run.json").read_text())
    assert recorded["updater_config"]["threshold"] == 9


def test_resume_refuses_a_recorded_config_with_an_unknown_key(configured_run, tmp_path, capsys):
    import shutil

    out = tmp_path / "run"
    shutil.copytree(configured_run[0], out)
    manifest = out / "state" / "run.json"
    m = json.loads(manifest.read_text())
    m["updater_config"]["treshold"] = m["updater_config"].pop("threshold")
    manifest.write_text(json.dumps(m))
    before = sorted(p.name for p in out.rglob("*"))
    assert main(["run", "--resume", str(out), "--no-progress"]) == 2
    line = one_line(capsys.readouterr().err)
    assert line == (f"mapupdate run: error: {manifest}: unknown key 'treshold' in "
                    f"'updater_config' (did you mean 'threshold'?)")
    assert sorted(p.name for p in out.rglob("*")) == before


# --- the gymnasium environment -----------------------------------------------------------------
@pytest.fixture(scope="module")
def room_and_map():
    import sim

    room = tiny_room()
    return room, sim.World(room, 1, 0).ground_truth()


def test_the_gym_env_takes_the_config_as_a_dict(room_and_map):
    from scenarios.gym.env import WarehouseMapUpdateEnv

    room, reference = room_and_map
    env = WarehouseMapUpdateEnv(room, "W2", reference_map=reference, config=VALID)
    env.reset(seed=3)
    assert env.session.updater.config == UpdaterConfig.profile("robot", {"threshold": 9})
    assert env.session.localizer.config.max_particles == 900
    assert env.session.pipeline.pose_check.config == PoseCheckConfig.profile(
        "robot", {"slack_cells": 1, "max_gain": 0.02}).for_poses(own_localizer=True)
    env = WarehouseMapUpdateEnv(room, "W2", reference_map=reference, config=VALID,
                                profile="paper")
    env.reset(seed=3)
    assert env.session.updater.config == UpdaterConfig(threshold=9)
    assert env.session.pipeline.pose_check is None      # the paper profile has none
    env = WarehouseMapUpdateEnv(room, "W2", reference_map=reference,
                                updater_config=UpdaterConfig(threshold=8),
                                config={"pose_check": {"slack_cells": 1}}, pose_check=False)
    env.reset(seed=3)
    assert env.session.updater.config.threshold == 8
    assert env.session.pipeline.pose_check is None


def test_the_gym_env_refuses_a_misspelt_key_and_a_section_given_twice(room_and_map):
    from scenarios.gym.env import WarehouseMapUpdateEnv

    room, reference = room_and_map
    with pytest.raises(ConfigError, match=r"^config: unknown key 'treshold' in section "
                                          r"'updater' \(did you mean 'threshold'\?\)$"):
        WarehouseMapUpdateEnv(room, "W2", reference_map=reference,
                              config={"updater": {"treshold": 9}})
    with pytest.raises(ConfigError, match="updater configuration is given twice"):
        WarehouseMapUpdateEnv(room, "W2", reference_map=reference, config=VALID,
                              updater_config=UpdaterConfig())
