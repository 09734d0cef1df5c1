"""No two modules of the project import each other, not even inside a function: each module's
place in the import order of DESIGN.md is then plain from its imports."""

import ast
import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGES = ("gridmap", "sim", "localization", "updater", "evaluation", "robotlogs", "scenarios")


def _modules() -> dict[str, pathlib.Path]:
    out = {}
    for pkg in PACKAGES:
        for path in (ROOT / pkg).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def _imported(name: str, path: pathlib.Path, modules) -> set[str]:
    """The project's modules that ``name`` imports anywhere in its text."""
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else []
            prefix = ".".join(base + ([node.module] if node.module else []))
            targets = [prefix] + [f"{prefix}.{a.name}" for a in node.names]
        else:
            continue
        found.update(t for t in targets if t in modules and t != name)
    return found


def test_no_two_modules_import_each_other():
    modules = _modules()
    imports = {name: _imported(name, path, modules) for name, path in modules.items()}
    # a package and its own modules import each other by design (__init__ re-exports them)
    mutual = sorted(f"{a} <-> {b}" for a, targets in imports.items() for b in targets
                    if a < b and a in imports[b]
                    and not (b.startswith(a + ".") or a.startswith(b + ".")))
    assert mutual == []
