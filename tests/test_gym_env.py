"""The gymnasium environment: registered by its package, passes gymnasium's
checker, replays a seed exactly, vectorises, and reproduces the runner's figures when the
runner's own robot drives it."""

import ast
import dataclasses
import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import scenarios
import scenarios.gym  # noqa: F401 - registers WarehouseMapUpdate-v0
import sim
from scenarios.gym.episode import StepOutcome, default_reward, initial_map
from scenarios.gym.policies import RouteFollowingPolicy, evaluate, run_episode
from scenarios.runner import RunOptions, build_initial_map, run_update_session
from scenarios.session import session_seeds
from tiny_room import tiny_room

ENV_ID = "WarehouseMapUpdate-v0"


@pytest.fixture(scope="module")
def room():
    return tiny_room()


@pytest.fixture(scope="module")
def m1(room):
    return initial_map(room, 5)


def make(room, m1, **kw):
    return gym.make(ENV_ID, scenario=room, session="W2", reference_map=m1, **kw)


def play(env, seed, n, action_seed=0):
    rng = np.random.default_rng(action_seed)
    obs, info = env.reset(seed=seed)
    out = [(obs, info)]
    for _ in range(n):
        a = rng.uniform(env.action_space.low, env.action_space.high).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(a)
        out.append((obs, reward, terminated, truncated, info))
        if terminated or truncated:
            break
    return out


def same(a, b) -> bool:
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (tuple, list)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and np.array_equal(a, b)
    return a == b


def test_the_env_package_registers_the_env_as_gymnasium_documents():
    # the testbed alone does not load gymnasium; its env package registers the env, without
    # loading the simulator until the first make
    code = ("import sys, scenarios\n"
            "print('gymnasium' in sys.modules)\n"
            "import scenarios.gym, gymnasium\n"
            "print('WarehouseMapUpdate-v0' in gymnasium.registry, 'pymunk' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "True", "False"]
    # gymnasium's "module:EnvId" form imports the package on the way
    code = ("import gymnasium\n"
            "env = gymnasium.make('scenarios.gym:WarehouseMapUpdate-v0', quick=True)\n"
            "print(type(env.unwrapped).__name__)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["WarehouseMapUpdateEnv"]
    assert ENV_ID in gym.registry


def test_gymnasium_env_checker_passes(room, m1):
    env = make(room, m1, render_mode="rgb_array", map_observation=True)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)       # the checker reports what it dislikes as warnings
    assert [str(w.message) for w in caught] == []
    env.close()


def test_reset_with_a_seed_twice_gives_the_same_episode(room, m1):
    env = make(room, m1)
    a = play(env, 11, 60)
    b = play(env, 11, 60)
    assert len(a) == 61 and same(a, b)
    c = play(env, 12, 60)
    assert not same(a[1:], c[1:])
    # an unseeded reset draws the episode's seed from np_random: reproducible after a seed
    env.reset(seed=3)
    first = env.reset()[1]["seed"]
    env.reset(seed=3)
    assert env.reset()[1]["seed"] == first


def test_spaces_hold_what_the_env_returns(room, m1):
    env = make(room, m1, map_observation=True)
    obs, info = env.reset(seed=1)
    assert obs in env.observation_space
    assert obs["scan"].dtype == np.float32 and obs["scan"].shape == (271,)
    assert np.all(obs["scan"] <= 10.0) and np.all(obs["scan"] >= 0.0)
    assert obs["map"].shape == sim.grid_frame(room).shape
    np.testing.assert_allclose(obs["estimate"], [1.0, 1.0, 0.0], atol=1e-6)
    for key in ("true_pose", "estimated_pose", "localization_error", "cells_changed",
                "collisions", "people_contacts"):
        assert key in info
    for _ in range(20):
        obs, r, term, trunc, info = env.step(env.action_space.sample())
        assert obs in env.observation_space and isinstance(r, float)
    assert info["time"] == pytest.approx(20 * 0.05)
    with pytest.raises(ValueError):
        env.step([np.nan, 0.0])


def test_vector_env_in_sync_mode(room, m1):
    envs = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="sync", scenario=room,
                        session="W2", reference_map=m1)
    obs, info = envs.reset(seed=[1, 2])
    assert obs["scan"].shape == (2, 271) and obs["estimate"].shape == (2, 3)
    for _ in range(10):
        obs, reward, term, trunc, info = envs.step(np.array([[0.3, 0.1], [0.2, -0.1]],
                                                            np.float32))
    assert reward.shape == (2,) and info["time"].tolist() == pytest.approx([0.5, 0.5])
    assert not np.array_equal(obs["scan"][0], obs["scan"][1])
    envs.close()


def test_driving_into_a_wall_is_a_collision_and_costs_reward(room, m1):
    env = make(room, m1).unwrapped
    env.reset(seed=4)                  # at (1, 1) facing +x: the west wall 0.7 m behind
    total, info = 0.0, None
    for _ in range(60):
        _, r, term, trunc, info = env.step([-0.6, 0.0])
        total += r
    assert info["collisions"] > 0
    assert info["true_pose"][0] >= 0.3 - 1e-6
    assert total <= -10.0 * info["collisions"] + 1000


def test_a_custom_reward_gets_the_step_outcome(room, m1):
    seen = []

    def reward(o: StepOutcome) -> float:
        seen.append(o)
        return -o.localization_error

    env = make(room, m1, reward_fn=reward)
    env.reset(seed=2)
    _, r, *_ = env.step([0.2, 0.0])
    assert len(seen) == 1 and r == -seen[0].localization_error
    assert seen[0].dt == pytest.approx(0.05)
    assert default_reward(StepOutcome(0.1, 5, 1, 1, 0, 0.0, False, 1, False)) == 4 - 10


def test_episode_ends_at_the_time_limit_with_the_scores():
    room = tiny_room(max_duration=3.0)
    env = gym.make(ENV_ID, scenario=room, session="W2", reference_map=initial_map(room, 5),
                   control_period=0.1)
    env.reset(seed=0)
    steps, trunc, info = 0, False, {}
    while not trunc:
        _, _, term, trunc, info = env.step([0.0, 0.0])
        assert not term
        steps += 1
    assert steps == 30 and "scores" in info
    assert set(info["scores"]) >= {"name", "map_metrics", "change_detection", "ghost_cells",
                                    "localization", "resources"}
    with pytest.raises(RuntimeError):
        env.unwrapped.step([0.0, 0.0])
    with pytest.raises(ValueError):
        gym.make(ENV_ID, scenario=room, session="W2", control_period=0.07)
    with pytest.raises(sim.ScenarioError):
        gym.make(ENV_ID, scenario=room, session="W1")


def test_render_draws_a_top_view(room, m1):
    env = make(room, m1, render_mode="rgb_array", render_scale=2)
    env.reset(seed=1)
    for _ in range(30):
        env.step([0.3, 0.2])
    img = env.render()
    h, w = sim.grid_frame(room).shape
    assert img.shape == (2 * h, 2 * w, 3) and img.dtype == np.uint8
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 4     # map, robot, scan, person


def _runner_session(scn, seed, session=1):
    seeds = session_seeds(seed, len(scn.sessions))
    m1 = build_initial_map(scn, 0, seeds[0])
    return run_update_session(scn, session, m1.updated, m1.updated, seeds[session],
                              RunOptions(progress=False, compare_paper=False))


def _without_resources(scores):
    return {k: v for k, v in scores.items() if k != "resources"}


def test_the_route_following_policy_gives_the_runners_figures(room):
    res = _runner_session(room, 5)
    table = evaluate(RouteFollowingPolicy(), room, seeds=[5], session="W2")
    assert _without_resources(table.scores[0]) == _without_resources(res.metrics)
    row = table.rows[0]
    assert row["terminated"] and row["collisions"] == 0
    assert row["time_s"] == res.metrics["resources"]["simulated_s"]
    assert table.scores[0]["resources"]["scans"] == res.metrics["resources"]["scans"]
    assert "| seed |" in str(table)


@pytest.mark.slow
def test_the_route_following_policy_gives_the_runners_figures_in_the_warehouse():
    scn = sim.quick_variant(sim.load_scenario(scenarios.find_scenario()))
    res = _runner_session(scn, 7)
    table = evaluate(RouteFollowingPolicy(), None, seeds=[7], session="W2", quick=True)
    assert _without_resources(table.scores[0]) == _without_resources(res.metrics)


def test_evaluate_tables_one_row_per_seed(room, m1):
    env = make(room, m1).unwrapped
    row, scores = run_episode(env, RouteFollowingPolicy(), 8)
    assert row["seed"] == 8 and row["terminated"] and scores["name"] == "W2"
    table = evaluate(RouteFollowingPolicy(), room, seeds=[1, 2], session="W2",
                     reference_map=m1, control_period=0.1)
    assert table.column("seed") == [1, 2] and len(table.scores) == 2


# --- hostile constructor arguments: refused before any work, naming the argument and value ----
def construct(room, m1, **kw):
    from scenarios.gym.env import WarehouseMapUpdateEnv

    return WarehouseMapUpdateEnv(scenario=room, session="W2", reference_map=m1, **kw)


def refused(room, m1, name, value, **kw):
    with pytest.raises(ValueError) as err:
        construct(room, m1, **{name: value}, **kw)
    assert name in str(err.value) and repr(value) in str(err.value), str(err.value)


@pytest.mark.parametrize("value", [float("inf"), float("nan"), 0.0, -0.05, 1e6, "0.1", True])
def test_a_bad_control_period_is_refused(room, m1, value):
    refused(room, m1, "control_period", value)


@pytest.mark.parametrize("value", [-1, 1.5, "3", True])
def test_a_bad_map_seed_is_refused(room, m1, value):
    refused(room, m1, "map_seed", value)


@pytest.mark.parametrize("value", [0, -2, 10**9, 2.5])
def test_a_bad_render_scale_is_refused(room, m1, value):
    refused(room, m1, "render_scale", value, render_mode="rgb_array")


def test_a_render_scale_over_the_picture_bound_is_refused(room, m1):
    from scenarios.gym.env import MAX_RENDER_SIDE

    with pytest.raises(ValueError, match="render_scale 4096 draws"):
        construct(room, m1, render_mode="rgb_array", render_scale=MAX_RENDER_SIDE)


@pytest.mark.parametrize("value", ["human", "rgb", ""])
def test_an_unknown_render_mode_is_refused(room, m1, value):
    refused(room, m1, "render_mode", value)


@pytest.mark.parametrize("name, value", [
    ("waypoint_tolerance", -0.1), ("waypoint_tolerance", float("nan")),
    ("goal_tolerance", -1e-3), ("goal_tolerance", float("inf")),
    ("lost_distance", float("nan")), ("lost_distance", -0.5), ("lost_distance", "far")])
def test_bad_tolerances_and_lost_distance_are_refused(room, m1, name, value):
    refused(room, m1, name, value)


def test_good_edge_arguments_are_accepted(room, m1):
    env = construct(room, m1, control_period=0.1, map_seed=0, render_mode="rgb_array",
                    render_scale=1, lost_distance=float("inf"), waypoint_tolerance=0.0,
                    goal_tolerance=0.0)
    assert env.control_period == pytest.approx(0.1) and env.lost_distance == float("inf")


# --- the settings: keywords or an EnvOptions record, an unknown name refused in one line ------
def test_a_misspelt_setting_is_refused_in_one_line_naming_the_nearest(room, m1):
    from scenarios.gym.env import EnvOptions, EnvOptionsError

    with pytest.raises(EnvOptionsError) as err:
        construct(room, m1, quik=True)
    assert str(err.value) == "WarehouseMapUpdateEnv: unknown setting 'quik' (did you mean 'quick'?)"
    # through gymnasium.make too (a TypeError there would carry every keyword's value)
    with pytest.raises(EnvOptionsError, match=r"^WarehouseMapUpdateEnv: unknown setting "
                                              r"'profil' \(did you mean 'profile'\?\)$"):
        make(room, m1, profil="paper")
    with pytest.raises(EnvOptionsError, match=r"^WarehouseMapUpdateEnv: unknown setting "
                                              r"'rendre_scale' \(did you mean 'render_scale'\?\)$"):
        construct(room, m1, options={"rendre_scale": 3})
    # nothing near: the line lists the settings
    with pytest.raises(EnvOptionsError) as err:
        construct(room, m1, zzzz=1)
    message = str(err.value)
    assert "\n" not in message and "'zzzz'" in message
    assert all(f.name in message for f in dataclasses.fields(EnvOptions))
    with pytest.raises(EnvOptionsError, match="options must be an EnvOptions"):
        construct(room, m1, options=3)


def test_settings_as_a_record_play_as_keywords_do(room, m1):
    from scenarios.gym.env import EnvOptions

    given = dict(control_period=0.1, lost_distance=0.4, map_observation=True)
    by_keywords = construct(room, m1, **given)
    record = EnvOptions(control_period=0.1, lost_distance=2.0, map_observation=True)
    by_record = construct(room, m1, options=record, lost_distance=0.4)    # keywords win
    assert by_record.options == by_keywords.options == EnvOptions(reference_map=m1, **given)
    assert record.lost_distance == 2.0                    # the record given is left as it was
    assert same(play(by_keywords, 11, 30), play(by_record, 11, 30))
    with pytest.raises(dataclasses.FrozenInstanceError):
        record.quick = True


def test_no_function_of_the_env_package_takes_more_than_12_parameters():
    package = Path(scenarios.gym.__file__).parent
    found = []
    for path in sorted(package.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                a = node.args
                names = [p.arg for p in a.posonlyargs + a.args + a.kwonlyargs]
                names += [p.arg for p in (a.vararg, a.kwarg) if p is not None]
                n = len([x for x in names if x not in ("self", "cls")])
                if n > 12:
                    found.append(f"{path.name}:{node.lineno} {node.name} ({n})")
    assert found == []
