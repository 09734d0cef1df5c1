"""Where scenario files live: built-in names resolve to the YAML files shipped in this package."""

from __future__ import annotations

from pathlib import Path

from gridmap import MapUpdatingError
from gridmap.suggest import did_you_mean

HERE = Path(__file__).resolve().parent
DEFAULT_SCENARIO = "aws_small_warehouse"


class ScenarioNotFound(MapUpdatingError, FileNotFoundError):
    """A scenario name or path that names no file."""


def builtin_scenarios() -> list[str]:
    return sorted(p.stem for p in HERE.glob("*.yaml"))


def find_scenario(name_or_path: str | Path | None = None) -> Path:
    """The YAML file of a built-in scenario name, or the given path if it exists."""
    if name_or_path is None:
        name_or_path = DEFAULT_SCENARIO
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml") or p.exists():
        if not p.exists():         # a device or a folder is refused when it is read
            raise ScenarioNotFound(f"scenario file {p} does not exist")
        return p
    candidate = HERE / f"{name_or_path}.yaml"
    if candidate.is_file():
        return candidate
    names = builtin_scenarios()
    raise ScenarioNotFound(f"no scenario named {str(name_or_path)!r}"
                           f"{did_you_mean(name_or_path, names)}; built-in: "
                           f"{', '.join(names) or 'none'}")
