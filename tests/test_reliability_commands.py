"""What the commands refuse, round three: outputs never over an input, never into a folder
that holds other files, never a folder made where the user named none; a study that names a
run outside it; a Ray address that is wrong or silent; a FIFO for a log; usage mistakes. Each
refusal is one line and exit 2, with every input as it was."""

from __future__ import annotations

import hashlib
from pathlib import Path

from mapupdate import main
from scenarios.catalog import find_scenario


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def one_line_error(capsys, command: str, *words: str) -> None:
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"mapupdate {command}: error:") and "\n" not in err, err
    for w in words:
        assert w in err, err


def test_a_run_never_goes_into_a_folder_holding_other_files(tmp_path, capsys):
    (tmp_path / "mine").mkdir()
    report = tmp_path / "mine" / "report.md"
    report.write_text("my own notes\n")
    assert main(["run", "--quick", "--out", str(tmp_path / "mine"), "--no-progress"]) == 2
    one_line_error(capsys, "run", "holds other files (report.md)", "new or empty folder")
    assert report.read_text() == "my own notes\n"
    assert sorted(p.name for p in (tmp_path / "mine").iterdir()) == ["report.md"]


def test_the_recording_never_goes_over_the_scenario_or_the_config(tmp_path, capsys):
    scenario = tmp_path / "scenario.yaml"
    scenario.write_bytes(find_scenario(None).read_bytes())
    config = tmp_path / "robot.yaml"
    config.write_text("updater:\n  threshold: 7\n")
    before = {p: digest(p) for p in (scenario, config)}
    for target, name in ((scenario, "scenario"), (config, "--config")):
        assert main(["run", str(scenario), "--quick", "--config", str(config), "--out",
                     str(tmp_path / "run"), "--rerun", str(target), "--no-progress"]) == 2
        one_line_error(capsys, "run", "--rerun", name)
    assert {p: digest(p) for p in (scenario, config)} == before
    assert not (tmp_path / "run").exists()


def test_render_makes_no_folder_the_user_did_not_make(tmp_path, capsys):
    out = tmp_path / "missing" / "w.png"
    assert main(["render", "--out", str(out)]) == 2
    one_line_error(capsys, "render", "does not exist", "make it first")
    assert not (tmp_path / "missing").exists()


def test_a_usage_mistake_is_one_line_naming_the_help(capsys):
    import pytest

    for argv, words in ((["generate", "--seed", "1e9", "--out", "g.yaml"],
                         "argument --seed: invalid int value: '1e9'"),
                        (["update", "--map", "m.yaml"], "required: --log, --out")):
        with pytest.raises(SystemExit) as stop:
            main(argv)
        assert stop.value.code == 2
        one_line_error(capsys, argv[0], words, f"(see mapupdate {argv[0]} --help)")


def test_summarise_stays_inside_the_study_and_names_a_damaged_file(tmp_path, capsys):
    import json

    study = tmp_path / "study"
    (study / "runs" / "a").mkdir(parents=True)
    outside = tmp_path / "result.json"
    outside.write_text(json.dumps({"run": {}, "rows": [{"scenario": "stolen"}]}))
    sweep = {"format": 1, "spec": {}, "runs": ["../.."]}
    (study / "sweep.json").write_text(json.dumps(sweep))
    assert main(["sweep", "--summarise", str(study)]) == 2
    one_line_error(capsys, "sweep", "run '../..' is not a run name of this study")
    assert not (study / "results.csv").exists()
    (study / "sweep.json").write_text(json.dumps({**sweep, "runs": ["a"]}))
    (study / "runs" / "a" / "result.json").write_text('{"run": {"point": {}}, "rows": [')
    assert main(["sweep", "--summarise", str(study)]) == 2
    one_line_error(capsys, "sweep", "result.json: unreadable run result (JSONDecodeError")
    (study / "sweep.json").write_text('{"spec": 3, "runs": 4}')
    assert main(["sweep", "--summarise", str(study)]) == 2
    one_line_error(capsys, "sweep", "sweep.json: not a study file of this project")


def test_a_ray_address_that_is_wrong_or_silent_is_one_line_within_seconds(tmp_path, capsys):
    import socket
    import time

    import pytest

    pytest.importorskip("ray")
    spec = tmp_path / "spec.yaml"
    spec.write_text("scenarios: [aws_small_warehouse]\nquick: true\n")
    with socket.socket() as s:                     # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        silent = f"127.0.0.1:{s.getsockname()[1]}"
    for address, words in (("not an address", "not an address"),
                           (silent, "no Ray cluster answers there")):
        t0 = time.monotonic()
        assert main(["sweep", str(spec), "--out", str(tmp_path / "study"), "--ray",
                     address, "--no-progress"]) == 2
        assert time.monotonic() - t0 < 10
        one_line_error(capsys, "sweep", f"--ray {address!r}" if " " in address else address,
                       words)
    assert not (tmp_path / "study").exists()


def test_a_fifo_as_the_log_is_one_line_not_a_hang(tmp_path, capsys):
    import os

    from gridmap import OccupancyGrid, save_map

    save_map(OccupancyGrid.empty(4, 3, 0.05), tmp_path / "m.yaml")
    fifo = tmp_path / "log.clf"
    os.mkfifo(fifo)
    for argv in (["map", "--log", str(fifo), "--out", str(tmp_path / "a.yaml")],
                 ["update", "--map", str(tmp_path / "m.yaml"), "--log", str(fifo), "--out",
                  str(tmp_path / "b.yaml")]):
        assert main([*argv, "--no-progress"]) == 2
        one_line_error(capsys, argv[0], "the log is a FIFO (a named pipe)")
    assert not (tmp_path / "a.yaml").exists() and not (tmp_path / "b.yaml").exists()
