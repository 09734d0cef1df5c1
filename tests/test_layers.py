"""The import direction of DESIGN.md: the robot software never pulls in the simulator or the
optional front ends, so it runs on real data with nothing else installed."""

import pathlib
import re
import subprocess
import sys

import pytest

FORBIDDEN = ("sim", "scenarios", "studies", "pymunk", "rerun", "gymnasium", "matplotlib")
ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGES = ("gridmap", "sim", "updater", "localization", "evaluation", "robotlogs", "onboard",
            "scenarios", "studies", "mapupdate", "mapstore")


@pytest.mark.parametrize("package", ["gridmap", "updater", "localization", "evaluation",
                                     "robotlogs", "onboard", "onboard.replay", "onboard.logmap",
                                     "mapstore",
                                     "onboard.methods", "onboard.ros1.node", "onboard.ros_common.settings"])
def test_core_packages_do_not_import_the_simulator_or_front_ends(package):
    code = (
        "import sys, importlib\n"
        f"importlib.import_module({package!r})\n"
        f"bad = [m for m in {FORBIDDEN!r} if m in sys.modules]\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "", f"{package} pulled in {out.stdout.strip()}"


@pytest.mark.parametrize("package, allowed", [
    ("gridmap", set()), ("updater", {"gridmap"}), ("localization", {"gridmap"}),
    ("evaluation", {"gridmap"}), ("robotlogs", {"gridmap"}), ("sim", {"gridmap"}),
    ("onboard", {"gridmap", "updater", "localization", "robotlogs", "mapstore"}),
    ("mapstore", {"gridmap"}),
    # (scenarios/__main__.py: ``python -m scenarios`` is the command line)
    # (and the map store, for the fleet's store mode: robots committing as live nodes do)
    ("scenarios", {"gridmap", "sim", "updater", "localization", "evaluation", "robotlogs",
                   "onboard", "mapupdate", "mapstore"}),
    ("studies", {"gridmap", "sim", "onboard", "scenarios"}),
    ("mapupdate", {"gridmap", "localization", "robotlogs", "evaluation", "onboard", "scenarios",
                   "studies", "sim", "mapstore"})])
def test_each_core_package_imports_only_what_design_md_allows(package, allowed):
    # every import statement, those inside functions too (imported on use)
    graph = import_graph()
    used = {dep.split(".")[0] for mod, deps in graph.items() if mod.split(".")[0] == package
            for dep in deps} - {package}
    assert used <= allowed, f"{package} imports {sorted(used - allowed)}"


def test_no_two_modules_import_each_other_directly_or_round_a_cycle():
    graph = import_graph()
    cycles = []
    state: dict[str, int] = {}          # 1 on the stack, 2 done

    def visit(mod, stack):
        state[mod] = 1
        for dep in sorted(graph.get(mod, ())):
            if state.get(dep) == 1:
                cycles.append(stack[stack.index(dep):] + [dep])
            elif dep not in state:
                visit(dep, stack + [dep])
        state[mod] = 2
    for mod in sorted(graph):
        if mod not in state:
            visit(mod, [mod])
    assert not cycles, "import cycles: " + "; ".join(" -> ".join(c) for c in cycles)


def import_graph() -> dict[str, set[str]]:
    """Module -> the project's modules it imports, read from the source (no import runs).
    A package's ``__init__`` counts as the package; ``from pkg import name`` counts as an
    import of ``pkg.name`` when that is a module, else of ``pkg``."""
    import ast

    modules = {}
    for pkg in PACKAGES:
        for path in (ROOT / pkg).rglob("*.py"):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            is_init = parts[-1] == "__init__"
            if is_init:
                parts = parts[:-1]
            modules[".".join(parts)] = (path, is_init)
    graph = {}
    for name, (path, is_init) in modules.items():
        package = name if is_init else name.rpartition(".")[0]
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")
                    up = up[:len(up) - node.level + 1]
                    base = ".".join(up + ([base] if base else []))
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base
                           for a in node.names]
            else:
                continue
            for t in targets:
                while t and t not in modules:
                    t = t.rpartition(".")[0]
                if t and t != name:
                    deps.add(t)
        graph[name] = deps
    return graph


def test_sim_does_not_import_the_robot_software():
    code = (
        "import sys, sim\n"
        "bad = [m for m in ('updater', 'localization', 'onboard', 'scenarios') if m in sys.modules]\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_command_line_starts_without_compiling_kernels():
    code = "import sys, mapupdate.main\nprint('numba' in sys.modules)\n"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize("front_end, modules", [
    ("gymnasium", ["scenarios/gym/__init__.py", "scenarios/gym/env.py"]),
    ("rerun", ["scenarios/rerun_log.py"]), ("rospy", ["onboard/ros1/node.py"]),
    ("rclpy", ["onboard/ros2/bond.py", "onboard/ros2/lifecycle.py", "onboard/ros2/node.py"]),
    ("ray", ["studies/sweep_ray.py"]), ("scipy", ["studies/study_report.py"]),
    ("psycopg", ["mapstore/backends.py"])])
def test_each_optional_package_is_imported_in_one_place_only(front_end, modules):
    pattern = re.compile(rf"^\s*(import|from)\s+{front_end}\b", re.M)
    users = sorted(str(p.relative_to(ROOT)) for pkg in PACKAGES
                   for p in (ROOT / pkg).rglob("*.py") if pattern.search(p.read_text()))
    assert users == modules
