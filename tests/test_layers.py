"""The import direction of DESIGN.md: the robot software never pulls in the simulator or the
optional front ends, so it runs on real data with nothing else installed."""

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
