"""The robot software stands alone: `mapupdate update` loads none of the simulator, the testbed
or their optional packages, a command whose extra is missing says what to install, and
`pip install .` without extras updates a map from a recording (slow: a fresh venv)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

import synthetic_hall as hall
from gridmap import load_map, save_map
from robotlogs.rosbag import write_bag

ROOT = Path(__file__).resolve().parents[1]
# (not scipy: numba itself imports it when it is installed, to check its version)
FORBIDDEN = ("sim", "scenarios", "studies", "pymunk", "gymnasium", "rerun", "matplotlib", "ray")

UPDATE_AND_LIST_MODULES = """
import json, sys
from mapupdate import main
code = main(sys.argv[2:])
print(json.dumps({"code": code, "numba": "numba" in sys.modules,
                  "loaded": sorted(m for m in json.loads(sys.argv[1]) if m in sys.modules)}))
"""


@pytest.fixture(scope="module")
def hall_bag(tmp_path_factory):
    d = tmp_path_factory.mktemp("hall")
    write_bag(d / "hall.bag", hall.bag_records(hall.record(seed=0, laps=1)), "ros1")
    save_map(hall.rasterise(hall.before()), d / "hall.yaml")
    return d


def test_mapupdate_update_loads_no_simulator_testbed_or_front_end(hall_bag, tmp_path):
    out = tmp_path / "updated.yaml"
    args = ["update", "--map", str(hall_bag / "hall.yaml"), "--log", str(hall_bag / "hall.bag"),
            "--out", str(out), "--no-progress"]
    p = subprocess.run([sys.executable, "-c", UPDATE_AND_LIST_MODULES, json.dumps(FORBIDDEN),
                        *args], capture_output=True, text=True, timeout=300)
    report = json.loads(p.stdout.strip().splitlines()[-1])
    assert report["code"] == 0, p.stderr
    assert report["numba"]                      # it did the work: the kernels ran
    assert report["loaded"] == []
    before = hall.rasterise(hall.before()).data
    assert (load_map(out).data != before).sum() > 100       # the hall's changes were found


NO_SIMULATOR = """
import sys
sys.modules["pymunk"] = None          # as on a robot installed without the [sim] extra
from mapupdate import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("argv, extra", [
    (["run", "--quick", "--out", "{tmp}/run"], "sim"),
    (["render", "--out", "{tmp}/w.png"], "sim"),
    (["generate", "--seed", "1", "--out", "{tmp}/g.yaml"], "sim")])
def test_a_command_without_its_extra_says_in_one_line_what_to_install(argv, extra, tmp_path):
    argv = [a.format(tmp=tmp_path) for a in argv]
    p = subprocess.run([sys.executable, "-c", NO_SIMULATOR, *argv], capture_output=True,
                       text=True, timeout=120)
    assert p.returncode == 2
    assert p.stderr.splitlines() == [
        f"mapupdate {argv[0]}: error: needs pymunk, which a robot install leaves out: pip "
        f"install 'lidar-map-updating[{extra}]' (or 'make setup' in a clone)"]
    assert list(tmp_path.iterdir()) == []       # nothing made before the refusal


@pytest.mark.parametrize("module", ["mapupdate", "scenarios"])
def test_version_is_the_installed_distributions(module):
    from importlib import metadata

    p = subprocess.run([sys.executable, "-m", module, "--version"], capture_output=True,
                       text=True, timeout=60)
    assert p.stdout.strip() == f"mapupdate {metadata.version('lidar-map-updating')}"


@pytest.mark.slow
def test_pip_install_without_extras_updates_a_map_from_a_recording(hall_bag, tmp_path):
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    pip = subprocess.run([venv / "bin/pip", "install", "--quiet", str(ROOT)],
                         capture_output=True, text=True, timeout=1800)
    assert pip.returncode == 0, pip.stderr[-2000:]
    listed = subprocess.run([venv / "bin/pip", "list", "--format=json"], capture_output=True,
                            text=True, check=True).stdout
    installed = {d["name"].lower() for d in json.loads(listed)}
    assert not installed & {"pymunk", "gymnasium", "rerun-sdk", "matplotlib", "scipy", "ray"}
    out = tmp_path / "updated.yaml"
    upd = subprocess.run([venv / "bin/mapupdate", "update", "--map", hall_bag / "hall.yaml",
                          "--log", hall_bag / "hall.bag", "--out", out, "--no-progress"],
                         capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert upd.returncode == 0, upd.stderr
    assert load_map(out).shape == hall.rasterise(hall.before()).shape
    run = subprocess.run([venv / "bin/mapupdate", "run", "--quick"], capture_output=True,
                         text=True, timeout=120, cwd=tmp_path)
    assert run.returncode == 2
    assert run.stderr.splitlines() == [
        "mapupdate run: error: needs pymunk, which a robot install leaves out: pip install "
        "'lidar-map-updating[sim]' (or 'make setup' in a clone)"]
