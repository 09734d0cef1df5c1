"""The house rules the code is kept to, checked from the source: the tests reach their helpers
by name (pytest's ``pythonpath`` in pyproject.toml, shared fixtures in tests/conftest.py), never
through sys.path or a fallback import; the product imports no test-only package; its
docstrings and comments name modules where they live; no copy of old code is kept in a folder
of its own."""

import ast
import io
import os
import pathlib
import re
import tokenize

ROOT = pathlib.Path(__file__).resolve().parents[1]
TESTS = ROOT / "tests"
PACKAGES = ("gridmap", "sim", "updater", "localization", "evaluation", "robotlogs", "onboard",
            "scenarios", "studies", "mapupdate", "mapstore")
HELPERS = {p.stem for p in TESTS.glob("*.py")}
TEST_ONLY = {"pytest", "hypothesis", "filterpy"}        # the ``dev`` extra's, not the product's
SYS_PATH_EDIT = re.compile(r"sys\.path\s*(\.\s*(insert|append|extend)\b|\[|\+=|=[^=])")


def files_of_the_tests(pattern: str = "**/*.py") -> list[pathlib.Path]:
    return sorted(p for p in TESTS.glob(pattern)
                  if "__pycache__" not in p.parts)


def test_no_test_edits_sys_path():
    """Not in the tests' own code, nor in the scripts they hand a subprocess (which get the
    checkout as their working folder or on PYTHONPATH instead)."""
    found = [f"{p.relative_to(ROOT)}:{n}" for p in files_of_the_tests()
             for n, line in enumerate(p.read_text().splitlines(), 1)
             if SYS_PATH_EDIT.search(line)]
    assert found == []


def fallback_imports(source: str) -> list[int]:
    """Lines of ``try: import a helper / except ImportError: ...`` blocks, and of imports of
    a helper as ``tests.<name>`` (which would load a second copy of a module the tests also
    import by name)."""
    tree = ast.parse(source)
    blocks = [node for node in ast.walk(tree) if isinstance(node, ast.Try)
              and any(isinstance(h.type, ast.Name) and h.type.id in ("ImportError",
                                                                     "ModuleNotFoundError")
                      for h in node.handlers)
              and any(name.split(".")[0] in HELPERS | {"tests"} for name in imported(node))]
    lines = {b.lineno for b in blocks}
    within = {n for b in blocks for n in range(b.lineno, b.end_lineno + 1)}
    for node in ast.walk(tree):
        if isinstance(node, (ast.Import, ast.ImportFrom)) and node.lineno not in within and any(
                name.split(".")[:2] in [["tests", h] for h in HELPERS] for name in imported(node)):
            lines.add(node.lineno)
    return sorted(lines)


def imported(node: ast.AST) -> list[str]:
    """The dotted names the imports in ``node`` load (``from a import b``: ``a`` and ``a.b``)."""
    names = []
    for n in ast.walk(node):
        if isinstance(n, ast.Import):
            names += [a.name for a in n.names]
        elif isinstance(n, ast.ImportFrom) and n.module and not n.level:
            names += [n.module] + [f"{n.module}.{a.name}" for a in n.names]
    return names


def test_helpers_are_imported_by_name_without_a_fallback():
    found = [f"{p.relative_to(ROOT)}:{n}" for p in files_of_the_tests("*.py")
             for n in fallback_imports(p.read_text())]
    assert found == []


def test_the_fallback_check_sees_the_old_pattern():
    old = ("try:\n    import synthetic_room as world\n"
           "except ImportError:  # tests collected as a package\n"
           "    from tests import synthetic_room as world\n")
    assert fallback_imports(old) == [1]
    assert fallback_imports("from tests.test_intel import figures\n") == [1]
    assert fallback_imports("import os\nfrom tests import postgres_tools\n") == [2]
    assert fallback_imports("from tests.data.golden import golden\n") == []
    assert fallback_imports("try:\n    import psycopg\nexcept ImportError:\n    psycopg = None\n") \
        == []
    assert SYS_PATH_EDIT.search("sys.path" + '.insert(0, str(ROOT / "tests"))')
    assert not SYS_PATH_EDIT.search("print(sys.path)")


def product_files():
    for pkg in PACKAGES:
        yield from sorted((ROOT / pkg).rglob("*.py"))


def test_the_product_imports_no_test_only_package():
    found = [f"{p.relative_to(ROOT)}: {name}" for p in product_files()
             for name in imported(ast.parse(p.read_text())) if name.split(".")[0] in TEST_ONLY]
    assert found == []


MODULES: dict[str, set[str]] = {}          # a module's name -> the packages that have one
for _path in product_files():
    if _path.stem != "__init__":
        MODULES.setdefault(_path.stem, set()).add(
            _path.parent.relative_to(ROOT).as_posix().replace("/", "."))
# packages that were renamed: a module named under the old name is named where it used to live
OLD_PACKAGES = ("robot",)
DOTTED = re.compile(r"(?<![\w./-])(" + "|".join(PACKAGES + OLD_PACKAGES)
                    + r")\.([A-Za-z_]\w*)")


def moved_mentions(source: str) -> list[str]:
    """``pkg.name`` in the comments and strings of ``source`` where ``pkg`` has no module (or
    subpackage, or name in its __init__) ``name`` but another package has a module ``name``:
    a module named where it used to live."""
    found = []
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type not in (tokenize.COMMENT, tokenize.STRING):
            continue
        for m in DOTTED.finditer(tok.string):
            pkg, name = m.groups()
            here = ROOT / pkg
            if (here / name).is_dir() or (here / f"{name}.py").exists() or name not in MODULES:
                continue
            if (here / "__init__.py").exists() and name in defined(here / "__init__.py"):
                continue
            found.append(f"{tok.start[0]}: {pkg}.{name} (a module of "
                         f"{', '.join(sorted(MODULES[name]))})")
    return found


def defined(path: pathlib.Path) -> set[str]:
    """The names a module binds at its top level: defined, assigned or imported."""
    names = set()
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names |= {(a.asname or a.name).split(".")[0] for a in node.names}
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names |= {n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)}
    return names


def test_docstrings_name_modules_where_they_live():
    found = [f"{p.relative_to(ROOT)}:{line}" for p in product_files()
             for line in moved_mentions(p.read_text())]
    assert found == []


def test_the_moved_module_check_sees_an_old_home():
    assert moved_mentions('"""The pipeline (``scenarios.pipeline.RobotPipeline``)."""\n') \
        == ["1: scenarios.pipeline (a module of onboard)"]
    assert moved_mentions('"""See robot.replay.update_from_log."""\n') \
        == ["1: robot.replay (a module of onboard)"]
    assert moved_mentions("x = scenario.robot.radius  # robot.radius [m]\n") == []
    assert moved_mentions("x = 1  # one of onboard.methods.METHODS\n") == []
    assert moved_mentions('key = "updater.threshold"\n') == []


def test_no_frozen_copy_of_old_code_is_kept():
    """Old code is in git: a comparison with it takes a revision (``benchmarks/run.py
    --baseline REV``; the golden files of the bit-for-bit tests, ``tests/data/golden/record.py
    --rev REV``), not a copy in a folder named ``*_before``."""
    found = []
    for folder, subfolders, _ in os.walk(ROOT):
        subfolders[:] = [d for d in subfolders if not d.startswith(".") and d != "__pycache__"]
        found += [os.path.relpath(os.path.join(folder, d), ROOT) for d in subfolders
                  if d.endswith("_before")]
    assert found == []


def test_no_file_of_the_product_is_over_800_lines_nor_a_function_over_12_parameters():
    """What test_house_updater checks of the updater, over the whole product: a file a reader
    can take in, and no long argument list on the Python side (numba kernels aside, told
    apart by their decorator)."""
    from test_house_updater import MAX_LINES, MAX_PARAMETERS, functions, is_kernel, parameters

    long_files = [f"{p.relative_to(ROOT)}: {n}" for p in product_files()
                  if (n := len(p.read_text().splitlines())) > MAX_LINES]
    long_lists = [f"{p.relative_to(ROOT)}: {f.name} ({parameters(f)})" for p in product_files()
                  for f in functions(ast.parse(p.read_text()))
                  if parameters(f) > MAX_PARAMETERS and not is_kernel(f)]
    assert long_files == [] and long_lists == []
