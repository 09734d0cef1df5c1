"""The import direction of DESIGN.md: the robot software never pulls in the simulator or the
optional front ends, so it runs on real data with nothing else installed."""

import pathlib
import re
import subprocess
import sys

import pytest

FORBIDDEN = ("sim", "scenarios", "pymunk", "rerun", "gymnasium")


@pytest.mark.parametrize("package", ["gridmap", "updater", "localization"])
def test_core_packages_do_not_import_the_simulator_or_front_ends(package):
    code = (
        "import sys, importlib\n"
        f"importlib.import_module({package!r})\n"
        f"bad = [m for m in {FORBIDDEN!r} if m in sys.modules]\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "", f"{package} pulled in {out.stdout.strip()}"


def test_sim_does_not_import_the_robot_software():
    code = (
        "import sys, sim\n"
        "bad = [m for m in ('updater', 'localization', 'scenarios') if m in sys.modules]\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_command_line_starts_without_compiling_kernels():
    code = "import sys, scenarios.cli\nprint('numba' in sys.modules)\n"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize("front_end, module", [("gymnasium", "scenarios/gym/env.py"),
                                               ("rerun", "scenarios/rerun_log.py")])
def test_each_optional_front_end_is_imported_by_one_module_only(front_end, module):
    root = pathlib.Path(__file__).resolve().parents[1]
    pattern = re.compile(rf"^\s*(import|from)\s+{front_end}\b", re.M)
    users = sorted(str(p.relative_to(root)) for pkg in ("gridmap", "sim", "updater",
                                                         "localization", "scenarios")
                   for p in (root / pkg).rglob("*.py") if pattern.search(p.read_text()))
    assert users == [module]
