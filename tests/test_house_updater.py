"""The updater's house, checked from its source: files a reader can take in (none over 800
lines), no long positional argument lists on the Python side (a numba kernel may take more:
it is told apart by its ``njit`` decorator, and the kernels that Python calls take a handful
of records and named tuples), docs/algorithm.md's "Where the code lives" naming code that
exists and that ``MapUpdater`` reaches, and no kernel left that nothing reaches."""

from __future__ import annotations

import ast
import importlib
import pathlib
import re

from updater import UpdaterConfig, steps
from updater._arguments import Beams

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "updater"
MAX_LINES = 800
MAX_PARAMETERS = 12
# The kernels Python calls for a scan: a few records and named tuples each.
ENTRY_KERNELS = {"_scan": ("process_scan",), "_classify": ("run_classifier",),
                 "_decide": ("push_and_decide",)}
ENTRY_PARAMETERS = 8
# Functions nothing in the package calls, kept as the plain forms the tests check the ones
# that run against: the walks of one kind (tests/test_updater_speedup.py checks ``walk_scan``
# against them, and bench_updater.py times the walks with them), the per-beam distances from
# the configuration (the kernels' distances are checked against them) and the gate's
# direction bins worked out over every bin (tests/test_gate_recordings.py, ``bins_seen``).
UNREACHED = {("_walks", "walk_beams"), ("_walks", "flag_unknown_seen_through"),
             ("steps", "beam_distances"), ("gating", "directions_seen")}


def modules() -> dict[str, ast.Module]:
    return {p.stem: ast.parse(p.read_text()) for p in sorted(PACKAGE.glob("*.py"))}


def is_kernel(node: ast.FunctionDef) -> bool:
    """Decorated with numba's ``njit`` (or ``intrinsic``, numba's typing of a kernel's part)."""
    for d in node.decorator_list:
        target = d.func if isinstance(d, ast.Call) else d
        if isinstance(target, ast.Name) and target.id in ("njit", "intrinsic"):
            return True
    return False


def parameters(node: ast.FunctionDef) -> int:
    a = node.args
    names = [p.arg for p in a.posonlyargs + a.args + a.kwonlyargs]
    names += [p.arg for p in (a.vararg, a.kwarg) if p is not None]
    return len([n for n in names if n not in ("self", "cls")])


def functions(tree: ast.Module):
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            yield node


def test_no_file_of_the_updater_is_over_800_lines():
    long = {p.name: n for p in PACKAGE.glob("*.py")
            if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert long == {}


def test_no_python_function_takes_more_than_12_parameters():
    found = [f"updater/{name}.py:{f.lineno} {f.name} ({parameters(f)})"
             for name, tree in modules().items() for f in functions(tree)
             if not is_kernel(f) and parameters(f) > MAX_PARAMETERS]
    assert found == []


def test_the_kernels_python_calls_take_a_handful_of_arguments():
    trees = modules()
    for module, names in ENTRY_KERNELS.items():
        defs = {f.name: f for f in functions(trees[module])}
        for name in names:
            assert is_kernel(defs[name]) and parameters(defs[name]) <= ENTRY_PARAMETERS, name


def test_the_kernel_check_tells_kernels_apart():
    tree = ast.parse("@njit(cache=True)\ndef a(x): pass\n@njit\ndef b(x): pass\n"
                     "def c(x): pass\n@functools.cache\ndef d(): pass\n")
    assert [is_kernel(f) for f in functions(tree)] == [True, True, False, False]
    assert parameters(ast.parse("def f(self, a, *b, c, **d): pass").body[0]) == 4


def test_the_workspace_names_its_rows_as_the_kernels_do():
    rows = sum((names for _, names in steps.Workspace.ROWS), ()) + ("found",)
    assert rows == Beams._fields


# --- what MapUpdater reaches ------------------------------------------------------------------
class Package:
    """The updater's functions and methods, and the calls between them, from the source: a
    name called in a function, a module's attribute (``steps.x``, ``kernels().x``), a method
    of ``self`` or of a class the function names."""

    def __init__(self):
        self.trees = modules()
        self.defs, self.imports, self.classes = {}, {}, {}
        for module, tree in self.trees.items():
            for node in tree.body:
                if isinstance(node, ast.FunctionDef):
                    self.defs[module, node.name] = node
                elif isinstance(node, ast.ClassDef):
                    methods = [n for n in node.body if isinstance(n, ast.FunctionDef)]
                    self.classes[module, node.name] = [m.name for m in methods]
                    for m in methods:
                        self.defs[module, f"{node.name}.{m.name}"] = m
                elif isinstance(node, ast.ImportFrom) and node.level == 1:
                    for a in node.names:
                        source = node.module or a.name
                        self.imports[module, a.asname or a.name] = \
                            (source, None if node.module is None else a.name)
        # ``kernels()`` is the _kernels module, whose names come from the step modules
        self.kernel_names = {name: source for (module, name), source in self.imports.items()
                             if module == "_kernels"}

    def resolve(self, module: str, name: str) -> list[tuple[str, str]]:
        """The definitions ``name`` stands for in ``module``: a function, or a class's methods."""
        if (module, name) in self.defs:
            return [(module, name)]
        if (module, name) in self.classes:
            return [(module, f"{name}.{m}") for m in self.classes[module, name]]
        source = self.imports.get((module, name))
        if source is not None and source[1] is not None:
            return self.resolve(*source)
        return []

    def callees(self, module: str, qualname: str) -> set[tuple[str, str]]:
        out = set()
        owner = qualname.split(".")[0] if "." in qualname else None
        for node in ast.walk(self.defs[module, qualname]):
            if isinstance(node, ast.Name):
                out.update(self.resolve(module, node.id))
            elif isinstance(node, ast.Attribute):
                value = node.value
                if isinstance(value, ast.Name) and value.id == "self" and owner:
                    out.update(self.resolve(module, f"{owner}.{node.attr}"))
                elif isinstance(value, ast.Name) and (module, value.id) in self.imports \
                        and self.imports[module, value.id][1] is None:
                    out.update(self.resolve(self.imports[module, value.id][0], node.attr))
                elif isinstance(value, (ast.Call, ast.Name)) and node.attr in self.kernel_names:
                    if ast.unparse(value) in ("kernels()", "k"):
                        out.update(self.resolve("_kernels", node.attr))
        return out

    def reached(self) -> set[tuple[str, str]]:
        todo = [("map_updater", f"MapUpdater.{m}") for m in self.classes["map_updater",
                                                                       "MapUpdater"]]
        seen = set()
        while todo:
            key = todo.pop()
            if key in seen:
                continue
            seen.add(key)
            todo += self.callees(*key) - seen
        return seen


def documented() -> dict[str, list[str]]:
    """docs/algorithm.md's "Where the code lives": the names each updater module's row gives
    (in backquotes), by module."""
    text = (ROOT / "docs/algorithm.md").read_text()
    table = text.split("## Where the code lives", 1)[1].split("\n## ", 1)[0]
    out = {}
    for line in table.splitlines():
        cells = line.split("|")
        match = re.fullmatch(r"\s*`updater/(\w+)\.py`\s*", cells[1]) if len(cells) > 2 else None
        if match:
            out[match.group(1)] = re.findall(r"`([A-Za-z_]\w*)(?=[`(])", cells[2])
    return out


def test_the_table_of_where_the_code_lives_names_code_that_runs():
    package = Package()
    reached = package.reached()
    found = documented()
    assert {"steps", "_scan", "_classify", "_walks", "_flags", "_buffers", "_decide",
            "_output"} <= set(found)
    missing, idle = [], []
    keys = set(UpdaterConfig.__dataclass_fields__)       # configuration keys, not code
    for module, names in found.items():
        imported = importlib.import_module(f"updater.{module}")
        for name in (n for n in names if n not in keys):
            if not hasattr(imported, name) and not any(
                    hasattr(getattr(imported, c), name) for _, c in package.classes
                    if _ == module):
                missing.append(f"{module}.{name}")
                continue
            defs = package.resolve(module, name) or [
                (m, q) for (m, q) in package.defs if m == module and q.endswith(f".{name}")]
            if defs and not set(defs) & reached:
                idle.append(f"{module}.{name}")
    assert missing == [] and idle == []


def test_every_function_of_the_updater_is_reached_but_the_few_kept_for_the_tests():
    package = Package()
    reached = package.reached()
    unreached = {(m, q) for (m, q) in package.defs
                 if (m, q) not in reached and "." not in q and m not in ("_kernels",)}
    assert unreached == UNREACHED


def test_the_reach_check_follows_calls_into_the_kernels():
    reached = Package().reached()
    for key in (("steps", "process_scan"), ("_scan", "process_scan"), ("_flags", "flag_scan"),
                ("_walks", "walk_scan"), ("_walks", "_walk_cells_on"), ("_output", "mark_enclosed"),
                ("_decide", "decide_all"), ("steps", "Workspace.arrays")):
        assert key in reached, key


def test_the_algorithm_page_names_updater_code_where_it_lives():
    """Every ``module.name`` of the updater's the page names (the rules' table: where each
    rule lives) exists there."""
    text = (ROOT / "docs/algorithm.md").read_text()
    named = {(m, n) for m, n in re.findall(
        r"`(steps|_[a-z]+|hit_tiles|gating|map_updater)\.(\w+)", text) if n != "py"}
    missing = [f"{m}.{n}" for m, n in sorted(named)
               if not hasattr(importlib.import_module(f"updater.{m}"), n)]
    assert len(named) > 10 and missing == []
