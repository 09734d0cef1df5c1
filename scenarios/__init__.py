"""Scenario files, the session runner, evaluation, reports, the command line and the
gymnasium environment: where the simulator, the localiser and the updater meet."""

from .catalog import DEFAULT_SCENARIO, ScenarioNotFound, builtin_scenarios, find_scenario

__all__ = ["DEFAULT_SCENARIO", "ScenarioNotFound", "builtin_scenarios", "find_scenario"]
