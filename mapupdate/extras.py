"""The optional extras (pyproject.toml): which package each command needs beyond the robot
software, and the one line that says what to install when it is missing."""

from __future__ import annotations

import importlib.util

# optional packages and the extra that installs each
EXTRAS = {"pymunk": "sim", "matplotlib": "sim", "gymnasium": "gym", "rerun": "rerun",
          "scipy": "studies", "ray": "ray"}


def require(*packages: str) -> None:
    """Refuse, before any work, a command whose optional packages are not installed."""
    for name in packages:
        if importlib.util.find_spec(name) is None:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)


def missing_extra(exc: BaseException) -> str | None:
    """The one line for a command whose optional package is not installed, else None."""
    if not isinstance(exc, ImportError):
        return None
    top = (exc.name or "").split(".")[0]
    if top not in EXTRAS:
        return None
    return (f"needs {top}, which a robot install leaves out: pip install "
            f"'lidar-map-updating[{EXTRAS[top]}]' (or 'make setup' in a clone)")
