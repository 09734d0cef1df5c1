"""Scenario files, the robot pipeline, the session runner, the log replay, reports, the command line and the
gymnasium environment: where the simulator, the localiser and the updater meet.

Importing this package registers the environment ``WarehouseMapUpdate-v0`` with gymnasium
(at once if gymnasium is loaded, else as soon as it is), without importing gymnasium itself:
the command line starts faster without it.
"""

import sys

from .catalog import DEFAULT_SCENARIO, ScenarioNotFound, builtin_scenarios, find_scenario

_LAZY = {"evaluate": "gym.policies", "EvaluationTable": "gym.policies",
         "RouteFollowingPolicy": "gym.policies", "WarehouseMapUpdateEnv": "gym.env",
         "generate": "generator", "write_generated": "generator"}


def __getattr__(name):
    # the gymnasium side (and the generator) is loaded on first use only
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


class _RegisterWhenImported:
    """A finder on ``sys.meta_path`` that lets gymnasium load as usual and then registers the
    environment; it removes itself at gymnasium's first import."""

    def find_spec(self, name, path=None, target=None):
        if name != "gymnasium":
            return None
        import importlib.util

        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        if spec is not None and spec.loader is not None:
            exec_module = spec.loader.exec_module

            def exec_and_register(module):
                exec_module(module)
                _register_env()

            spec.loader.exec_module = exec_and_register
        return spec


def _register_env() -> None:
    if f"{__name__}.gym.env" in sys.modules:
        return      # the env module registers the environment at the end of its own import
    if "gymnasium" in sys.modules:
        from .gym.env import register

        register()
    elif not any(isinstance(f, _RegisterWhenImported) for f in sys.meta_path):
        sys.meta_path.insert(0, _RegisterWhenImported())


_register_env()

__all__ = ["DEFAULT_SCENARIO", "ScenarioNotFound", "builtin_scenarios", "find_scenario",
           "evaluate", "EvaluationTable", "RouteFollowingPolicy", "WarehouseMapUpdateEnv",
           "generate", "write_generated"]
