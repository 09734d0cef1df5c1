"""Policies for ``WarehouseMapUpdate-v0`` and ``evaluate``, which plays one over seeds and tables
the session's scores.

A policy is a callable ``policy(observation, info) -> action``; if it has ``reset(env)``, that is
called after every ``env.reset`` (a policy that needs the environment gets it there).

    table = evaluate(RouteFollowingPolicy(), "aws_small_warehouse", seeds=[7, 8], quick=True)
    print(table)          # one row per seed: F1, precision, recall, CC, APE, return, ...
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .env import WarehouseMapUpdateEnv


class RouteFollowingPolicy:
    """The runner's robot: the simulator's route follower drives the session's route and waits
    for people. It reads the simulator's truth (the robot's pose, the people), as the runner's
    robot does, so it is a reference rather than a policy an agent could learn. With the
    default ``control_period`` (one physics step) an episode is the runner's session exactly,
    and the last ``info["scores"]`` are the runner's figures for the same seed."""

    def __init__(self):
        self._world = None

    def reset(self, env) -> None:
        self._world = env.unwrapped.world

    def __call__(self, observation, info) -> np.ndarray:
        if self._world is None:
            raise RuntimeError("RouteFollowingPolicy.reset(env) must be called after env.reset()")
        v, w = self._world.route_command()
        return np.array([v, w], np.float64)


COLUMNS = ("seed", "session", "steps", "return", "terminated", "time_s", "collisions",
           "f1", "precision", "recall", "cc", "ms", "opdf", "ghost_cells", "ape_rmse")


@dataclass
class EvaluationTable:
    """One row per episode; ``scores`` keeps each episode's whole ``info["scores"]``."""

    rows: list[dict] = field(default_factory=list)
    scores: list[dict] = field(default_factory=list)

    def column(self, name: str) -> list:
        return [r[name] for r in self.rows]

    def markdown(self) -> str:
        def fmt(v):
            if v is None:
                return "n/a"
            if isinstance(v, (bool, np.bool_)):
                return "yes" if v else "no"
            if isinstance(v, float):
                return f"{v:.3f}"
            return str(v)

        lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
        lines += ["| " + " | ".join(fmt(r[c]) for c in COLUMNS) + " |" for r in self.rows]
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.markdown()


def run_episode(env, policy, seed: int | None = None) -> tuple[dict, dict]:
    """Play one episode; returns (the table row, the episode's scores)."""
    obs, info = env.reset(seed=seed)
    if hasattr(policy, "reset"):
        policy.reset(env)
    total, steps = 0.0, 0
    while True:
        obs, reward, terminated, truncated, info = env.step(policy(obs, info))
        total += reward
        steps += 1
        if terminated or truncated:
            break
    s = info["scores"]
    cd, upd = s["change_detection"], s["map_metrics"]["updated_vs_truth"]
    row = {"seed": info["seed"], "session": s["name"], "steps": steps, "return": total,
           "terminated": bool(terminated), "time_s": info["time"],
           "collisions": info["collisions"], "f1": cd["f1"], "precision": cd["precision"],
           "recall": cd["recall"], "cc": upd["cc"], "ms": upd["ms"], "opdf": upd["opdf"],
           "ghost_cells": s["ghost_cells"],
           "ape_rmse": s["localization"]["previous_map"]["rmse"]}
    return row, s


def evaluate(policy, scenario=None, seeds=(7,), session: int | str = 1,
             **env_kwargs) -> EvaluationTable:
    """Play ``policy`` for one episode per seed in ``session`` of ``scenario`` and table the
    scores. ``env_kwargs`` go to the environment (``quick=True``, ``control_period``, ...)."""
    env = WarehouseMapUpdateEnv(scenario, session, **env_kwargs)
    table = EvaluationTable()
    try:
        for seed in seeds:
            row, scores = run_episode(env, policy, int(seed))
            table.rows.append(row)
            table.scores.append(scores)
    finally:
        env.close()
    return table
