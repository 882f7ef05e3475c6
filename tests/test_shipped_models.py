"""The policies in models/ load with their frozen normalisation and drive the executor."""

from __future__ import annotations

import dataclasses
import functools
import json
import math
from pathlib import Path
from statistics import NormalDist

import numpy as np
import pytest

from rayreach.acting.detour import Detour
from rayreach.env.reach import ReachEnv
from rayreach.evaluate.executor import Executor
from rayreach.planners import make_planner
from rayreach.planners.drl import MODELS_DIR
from rayreach.acting.resample import ActingPolicy
from rayreach.acting.final_approach import FinalApproach
from rayreach.learning.policy import load_policy
from rayreach.robots import get_robot

CASES = [("ur5", "exp1"), ("kr16", "exp4")]


@functools.cache
def _shipped_run(robot, scenario):
    """The shipped policy's planner and its run of ``scenario`` (seed 0), once per module:
    the policy is deterministic, so every test of the pair would replay the same episode."""
    planner = make_planner("drl", robot)
    with Executor(scenario) as ex:
        return planner, ex.run(planner, seed=0)


@pytest.mark.parametrize("robot,scenario", CASES)
def test_shipped_policy_loads_with_metadata_and_runs_an_episode(robot, scenario):
    bundle = MODELS_DIR / f"{robot}.zip"
    meta = json.loads(Path(bundle.with_suffix(".json")).read_text())
    assert meta["robot"] == robot and meta["timesteps"] > 0 and "rayreach train" in meta["command"]
    planner, record = _shipped_run(robot, scenario)
    assert planner.policy.normalization is not None  # training's statistics travel with the policy
    assert record.outcome in {"success", "collision", "timeout", "out of bounds"}
    assert 0 < record.steps <= 1024 and record.config["timesteps"] == meta["timesteps"]
    assert record.config["safety"] == {"workspace_guard": 0.01, "ray_shield": 0.05, "slide": 0.1, "memory_steps": 10,
                                       "arm_clearance": 0.01, "arm_memory_steps": 100,
                                       "guard_tool": True, "tool_clearance": 0.02}  # the executor's defaults
    spec = get_robot(robot)  # the env fills in the robot's radius, step and tool
    assert record.config["final_approach"] == {"radius": spec.final_approach_radius, "margin": FinalApproach.margin,
                                               "ee_step": 0.005, "rot_step": spec.rot_step,
                                               "tool_length": spec.tool.length, "tool_radius": spec.tool.radius,
                                               "axial_radius": spec.final_approach_axial_radius,
                                               "axial_angle": FinalApproach.axial_angle,
                                               "stall_steps": 0, "stall_gain": 0.01, "turn": True}
    assert record.config["detour"] == dataclasses.asdict(Detour())
    assert np.isfinite(record.ee_path).all()


def test_shipped_ur5_policy_reaches_exp1_at_the_true_goal_size():
    _planner, record = _shipped_run("ur5", "exp1")
    assert record.outcome == "success" and not record.collision
    assert record.path_length <= 0.45  # the paper's DRL path (0.462 m before the axial final approach)


def test_shipped_ur5_policy_reaches_both_goals_of_exp2():
    """exp2's first goal lies between two plates, below their tops (slot demonstrations)."""
    _planner, record = _shipped_run("ur5", "exp2")
    assert record.outcome == "success" and not record.collision
    assert record.path_length < 0.85  # the paper's DRL path


@pytest.mark.parametrize("robot,kind", [("ur5", "goal_slot"), ("kr16", "shelf")])
def test_shipped_json_names_the_demonstrations_cloned_into_the_policy(robot, kind):
    meta = json.loads((MODELS_DIR / f"{robot}.json").read_text())
    assert [d["kind"] for d in meta["demonstrations"]] == [kind]
    # the KR16's last parts were trained as it acts, one obstacle per world; the UR5's were not
    assert ("--acting-layers --obstacles 1" in meta["command"]) == (robot == "kr16")
    assert meta["demonstrations"][0]["timesteps"] <= meta["timesteps"]  # PPO may go on after cloning


def test_shipped_kr16_policy_reaches_exp4_at_the_true_goal_size():
    _planner, record = _shipped_run("kr16", "exp4")
    assert record.outcome == "success" and not record.collision
    assert record.path_length < 1.2  # the paper's DRL path 0.91 m


def test_a_drl_model_for_the_other_robot_is_refused():
    with pytest.raises(ValueError, match="is a ur5 policy, not kr16"):
        make_planner("drl", "kr16", model=MODELS_DIR / "ur5.zip")


def test_drl_alone_runs_the_policy_without_the_acting_layers_and_restores_them():
    """``drl-alone`` in the executor gives the episode of a bare env stepped by the same
    policy, and the executor's next ``drl`` run has its layers back."""
    alone = make_planner("drl-alone", "ur5")
    with Executor("exp1") as ex:
        record = ex.run(alone, seed=0)
        again = ex.run(make_planner("drl", "ur5"), seed=0)
    assert record.planner == "drl-alone" and record.config["final_approach"] is None and record.config["detour"] is None
    assert record.config["safety"] == {"workspace_guard": 0.0, "ray_shield": 0.0, "slide": 0.0, "memory_steps": 0,
                                       "arm_clearance": 0.0, "arm_memory_steps": 100, "guard_tool": False,
                                       "tool_clearance": None}
    env = ReachEnv(robot="ur5", scenario="exp1")  # no final approach, no safety layer
    try:
        obs, info = env.reset(seed=0)
        path, done = [info["ee_position"]], False
        while not done:
            obs, _, terminated, truncated, info = env.step(alone.act(obs))
            path.append(info["ee_position"])
            done = terminated or truncated
    finally:
        env.close()
    np.testing.assert_allclose(record.ee_path, np.asarray(path), atol=1e-9)
    assert again.config == _shipped_run("ur5", "exp1")[1].config
    np.testing.assert_allclose(again.ee_path, _shipped_run("ur5", "exp1")[1].ee_path, atol=1e-9)


def test_rollout_counts_outcomes_per_world_kind():
    """``rollout`` on random worlds: the outcomes add up to the episodes, and each kind's
    counts are those of the worlds that drew it (the same worlds, replayed one by one)."""
    from rayreach.env.reach import episode_outcome
    from rayreach.evaluate.rollout import EVAL_SEED_OFFSET, rollout
    from rayreach.acting.shield import ACTING_SAFETY
    from rayreach.scenarios.random_world import world_kinds

    summary = rollout(MODELS_DIR / "kr16.zip", "random", episodes=4, progress=False)
    assert sum(summary.outcomes.values()) == 4 and summary.outcomes["success"] == summary.successes
    policy = load_policy(MODELS_DIR / "kr16.zip")
    acting = ActingPolicy(policy)
    env = ReachEnv(robot="kr16", scenario="random", goal_tolerance=0.01, safety=ACTING_SAFETY,
                   final_approach=FinalApproach(), detour=Detour())
    env.set_n_obstacles(policy.meta["state"]["obstacles"]["count"])
    expected: dict[str, dict[str, int]] = {}
    try:
        for episode in range(4):
            obs, _ = env.reset(seed=EVAL_SEED_OFFSET + episode)
            acting.reset(EVAL_SEED_OFFSET + episode)
            done = False
            while not done:
                obs, _, terminated, truncated, info = env.step(acting.act(obs))
                done = terminated or truncated
            for kind in world_kinds(env.scenario):
                counts = expected.setdefault(kind, {"episodes": 0, "success": 0, "collision": 0,
                                                    "out_of_bounds": 0, "timeout": 0})
                counts["episodes"] += 1
                counts[episode_outcome(info)] += 1
    finally:
        env.close()
    assert summary.by_kind == dict(sorted(expected.items()))


def _exp1_start_observation() -> np.ndarray:
    env = ReachEnv(robot="ur5", scenario="exp1")
    try:
        return env.reset(seed=0)[0]
    finally:
        env.close()


def _clipped_normal_mean(m: float, s: float) -> float:
    """E[clip(X, -1, 1)] for X ~ N(m, s^2)."""
    z = NormalDist()
    a, b = (-1.0 - m) / s, (1.0 - m) / s
    return -z.cdf(a) + (1.0 - z.cdf(b)) + m * (z.cdf(b) - z.cdf(a)) + s * (z.pdf(a) - z.pdf(b))


def test_a_drawn_action_follows_the_policys_gaussian_clipped_to_the_action_space():
    """Against SB3's own mean action and the policy's log standard deviation: per action
    axis whose mean lies inside the bounds, the draws average what a Gaussian clipped to
    [-1, 1] averages."""
    policy = load_policy(MODELS_DIR / "ur5.zip")
    obs = _exp1_start_observation()
    mean = policy.act(obs, deterministic=True)
    std = np.exp(policy.model.policy.log_std.detach().numpy())
    inside = np.flatnonzero(np.abs(mean) < 0.999)
    assert len(inside) >= 2
    rng = np.random.default_rng(0)
    draws = np.array([policy.sample(obs, rng) for _ in range(2000)])
    assert np.all(np.abs(draws) <= 1.0)
    for k in inside:
        expected = _clipped_normal_mean(float(mean[k]), float(std[k]))
        assert abs(draws[:, k].mean() - expected) < 4 * std[k] / math.sqrt(len(draws))


def test_the_acting_policy_draws_only_on_a_repeated_observation_and_repeats_with_its_seed():
    policy = load_policy(MODELS_DIR / "ur5.zip")
    obs = _exp1_start_observation()
    other = obs.copy()
    other[6] += 0.01  # the goal 1 cm further along x
    acting = ActingPolicy(policy)

    def run(seed: int) -> list[np.ndarray]:
        acting.reset(seed)
        return [acting.act(o) for o in (obs, other, other, other, obs)]

    actions = run(3)
    for i, o in ((0, obs), (1, other), (4, obs)):  # a new observation: the mean
        np.testing.assert_array_equal(actions[i], policy.act(o, deterministic=True))
    assert not np.allclose(actions[2], actions[1]) and not np.allclose(actions[3], actions[2])  # drawn, and anew
    np.testing.assert_array_equal(np.array(run(3)), np.array(actions))
    assert not np.allclose(run(4)[2], actions[2])
    bare = ActingPolicy(policy, resample=False)
    bare.reset(3)
    np.testing.assert_array_equal(bare.act(other), bare.act(other))


def test_the_kr16_turns_its_tool_to_reach_a_goal_beside_an_upright_plate():
    """A random world (seed 1,000,035) with a plate 6 cm beside the goal: the tool, tilted
    across the plate's edge, reaches the goal by turning towards its path; without the turn
    the final approach is refused and the run times out."""
    from rayreach.evaluate.rollout import rollout

    world = dict(episodes=1, seed=1_000_035, progress=False)
    assert rollout(MODELS_DIR / "kr16.zip", "random", **world).outcomes["success"] == 1
    assert rollout(MODELS_DIR / "kr16.zip", "random", final_approach=FinalApproach(turn=False),
                   **world).outcomes["timeout"] == 1


def test_the_ur5s_tool_is_held_off_a_box_it_saw():
    """A random world (seed 1,000,045) that starts with a box beside the tool: its rays see
    the box, the step after sweeps the tool's blind side into it, unless the arm's rule
    watches the tool too (``SafetyLayer.guard_tool``)."""
    from rayreach.evaluate.rollout import rollout
    from rayreach.acting.shield import ACTING_SAFETY

    world = dict(episodes=1, seed=1_000_045, progress=False)
    assert rollout(MODELS_DIR / "ur5.zip", "random", **world).outcomes["success"] == 1
    unguarded = dataclasses.replace(ACTING_SAFETY, guard_tool=False)
    assert rollout(MODELS_DIR / "ur5.zip", "random", safety=unguarded, **world).outcomes["collision"] == 1


def test_the_ur5s_tool_keeps_its_own_clearance_from_a_moving_cover():
    """A random world (seed 1,000,173) with a moving cover over the goal: held 1 cm off what
    its rays saw, the tool strikes the cover on its way in; held 2 cm off
    (``SafetyLayer.tool_clearance``, the acting default), it reaches the goal."""
    from rayreach.evaluate.rollout import rollout
    from rayreach.acting.shield import ACTING_SAFETY

    world = dict(episodes=1, seed=1_000_173, progress=False)
    assert ACTING_SAFETY.tool_clearance == 0.02
    assert rollout(MODELS_DIR / "ur5.zip", "random", **world).outcomes["success"] == 1
    near = dataclasses.replace(ACTING_SAFETY, tool_clearance=0.01)
    assert rollout(MODELS_DIR / "ur5.zip", "random", safety=near, **world).outcomes["collision"] == 1


def test_the_ur5_is_taken_round_a_goal_slot_it_hovers_above():
    """A random world (seed 3,000,000): the goal between two plates, a box on the way. The
    policy stalls short of them; the detour takes the tool round the slot's plates, into its
    open end, where the final approach finishes. Without the detour the run times out."""
    from rayreach.evaluate.rollout import rollout

    world = dict(episodes=1, seed=3_000_000, progress=False)
    assert rollout(MODELS_DIR / "ur5.zip", "random", **world).outcomes["success"] == 1
    assert rollout(MODELS_DIR / "ur5.zip", "random", detour=None, **world).outcomes["timeout"] == 1
