"""The soak-per-method benchmark's columns (``benchmarks/bench_soak_methods.py``): which
updater and settings each runs, and its command line's errors."""

import pytest

from benchmarks import bench_soak_methods as bsm
from updater import UpdaterConfig, UpdaterError


def test_each_column_names_its_updater_and_settings():
    assert bsm.run_options("paper") == {"method": "paper",
                                        "updater_config": UpdaterConfig.profile("paper")}
    assert bsm.run_options("robot") == {"method": "paper",
                                        "updater_config": UpdaterConfig.profile("robot")}
    assert bsm.run_options("paper") != bsm.run_options("robot")
    fuse = bsm.run_options("fuse", {"move_faces": False})
    assert fuse["method"] == "fuse"
    assert fuse["updater_config"] == UpdaterConfig.profile("robot", {"move_faces": False})
    robot = bsm.run_options("robot", {"move_faces": False})["updater_config"]
    assert not robot.move_faces and robot.unanimous_min == UpdaterConfig.profile(
        "robot").unanimous_min


def test_a_misspelt_key_is_refused_with_the_nearest():
    with pytest.raises(UpdaterError, match="move_faces"):
        bsm.run_options("robot", {"move_facs": False})


@pytest.mark.parametrize("argv, says", [
    (["--methods", "papr"], "did you mean 'paper'"),
    (["--set", "move_faces"], "--set takes KEY=VALUE"),
    (["--set", "face_min_hits=0"], "face_min_hits"),
    (["--set", "move_faces=["], "not valid YAML"),
    (["--sessions", "0"], "--sessions must be 1-1000"),
    (["--seed", "-1"], "--seed must be 0 or more"),
])
def test_a_mistake_on_the_command_line_is_one_line_before_any_session(argv, says, capsys):
    with pytest.raises(SystemExit) as e:
        bsm.main(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[0].startswith("usage:") and "error:" in err[-1] and says in err[-1]
