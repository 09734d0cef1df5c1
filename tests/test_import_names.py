"""Every top-level name the project installs is its own: none is the import name of another
package installed beside it. Robot Framework, whose import name is ``robot`` (the name the
robot software's package had; it is ``onboard`` now), is installed with the test extras, and
every name of the project is imported beside it in one interpreter."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from importlib import metadata
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def project_names() -> list[str]:
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())
    return sorted(p.rstrip("*") for p in data["tool"]["setuptools"]["packages"]["find"]["include"])


def test_no_other_installed_distribution_provides_a_name_of_the_project():
    names = project_names()
    assert "onboard" in names and "robot" not in names
    providers = metadata.packages_distributions()
    clashes = {n: providers[n] for n in names
               if any(d != "lidar-map-updating" for d in providers.get(n, []))}
    assert not clashes, f"installed distributions that provide the project's names: {clashes}"


def test_every_name_imports_beside_robot_framework():
    code = (
        "import importlib, json, sys\n"
        "import robot\n"
        f"names = {project_names()!r}\n"
        "out = {'robot': robot.__file__, 'robot_run_cli': hasattr(robot, 'run_cli')}\n"
        "out.update({n: importlib.import_module(n).__file__ for n in names})\n"
        "print(json.dumps(out))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT / "tests")
    assert done.returncode == 0, done.stderr[-2000:]
    files = json.loads(done.stdout)
    assert files.pop("robot_run_cli") is True               # Robot Framework's own robot
    assert "site-packages" in files.pop("robot")
    for name, path in files.items():
        assert Path(path).resolve().is_relative_to(ROOT), (name, path)
