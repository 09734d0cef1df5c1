"""The testbed: scenario files and their catalog, generated warehouses, the session runner,
checkpoints, reports, session bags, the gymnasium environment (``scenarios.gym``) and the
rerun and top-view drawing. The robot software it drives lives in ``robot``; the studies that
compare methods over many runs in ``studies``.

The gymnasium environment ``WarehouseMapUpdate-v0`` is registered by ``import scenarios.gym``
(or ``gymnasium.make("scenarios.gym:WarehouseMapUpdate-v0")``), so that importing the testbed
does not load gymnasium.
"""

import importlib

from .catalog import DEFAULT_SCENARIO, ScenarioNotFound, builtin_scenarios, find_scenario

_LAZY = {"evaluate": "gym.policies", "EvaluationTable": "gym.policies",
         "RouteFollowingPolicy": "gym.policies", "WarehouseMapUpdateEnv": "gym.env",
         "generate": "generator", "write_generated": "generator"}


def __getattr__(name):
    # gymnasium and the simulator are loaded on first use only
    if name in _LAZY:
        return getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["DEFAULT_SCENARIO", "ScenarioNotFound", "builtin_scenarios", "find_scenario",
           "evaluate", "EvaluationTable", "RouteFollowingPolicy", "WarehouseMapUpdateEnv",
           "generate", "write_generated"]
