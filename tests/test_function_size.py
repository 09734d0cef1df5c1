"""Functions stay short enough to read as named steps: none over 60 lines, from ``def`` to the
end of its body, in every package."""

import ast
import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGES = ("gridmap", "sim", "updater", "localization", "evaluation", "robotlogs", "scenarios",
            "onboard", "studies", "mapupdate", "mapstore")
MAX_LINES = 60


def test_no_function_is_longer_than_sixty_lines():
    long = []
    for pkg in PACKAGES:
        assert (ROOT / pkg / "__init__.py").is_file(), f"no package {pkg}"
        for path in sorted((ROOT / pkg).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    n = node.end_lineno - node.lineno + 1
                    if n > MAX_LINES:
                        long.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name} ({n})")
    assert long == []
