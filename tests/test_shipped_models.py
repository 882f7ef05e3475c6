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

from rayreach.acting import ActingConfig, ActingEnv, ActingPolicy
from rayreach.acting.config import ROBOT_RADII
from rayreach.acting.detour import Detour
from rayreach.acting.final_approach import FinalApproach
from rayreach.env.episode import run_episode
from rayreach.env.reach import ReachEnv
from rayreach.evaluate.executor import Executor
from rayreach.learning.policy import load_policy
from rayreach.planners import make_planner
from rayreach.planners.drl import MODELS_DIR
from rayreach.robots import get_robot
from rayreach.scenarios import EXPERIMENTS
from rayreach.scenarios.splits import get_split

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
    assert record.outcome == "success" and not record.collision  # exp1 and exp4: 30 of 30 in the results
    assert 0 < record.steps < 1024 and record.config["timesteps"] == meta["timesteps"]
    share = record.acting_share  # every step counted once, the policy's among them
    assert sum(share.values()) == pytest.approx(1.0) and share["policy"] > 0.5
    assert share["policy"] * record.steps == pytest.approx(round(share["policy"] * record.steps))
    assert record.config["safety"] == {"workspace_guard": 0.01, "ray_shield": 0.05, "slide": 0.0, "memory_steps": 10,
                                       "arm_clearance": 0.01, "arm_memory_steps": 100,
                                       "guard_tool": True, "arm_rays": False,
                                       "tool_clearance": 0.02}  # the executor's defaults
    spec, radii = get_robot(robot), ROBOT_RADII[robot]  # the robot's step and tool, the acting radii
    assert record.config["final_approach"] == {"radius": radii.radius, "margin": FinalApproach.margin,
                                               "ee_step": 0.005, "rot_step": spec.rot_step,
                                               "tool_length": spec.tool.length, "tool_radius": spec.tool.radius,
                                               "axial_radius": radii.axial_radius,
                                               "axial_angle": FinalApproach.axial_angle,
                                               "stall_steps": 0, "stall_gain": 0.01, "turn": True, "give_way": True}
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


def test_shipped_json_says_how_each_policy_was_made():
    """The UR5's policy had a slot expert cloned into it by hand; the KR16's is the default
    recipe's own, from scratch by the one command, with nothing cloned."""
    ur5, kr16 = (json.loads((MODELS_DIR / f"{robot}.json").read_text()) for robot in ("ur5", "kr16"))
    assert [d["kind"] for d in ur5["demonstrations"]] == ["goal_slot"]
    assert ur5["demonstrations"][0]["timesteps"] <= ur5["timesteps"]  # PPO may go on after cloning
    assert kr16["demonstrations"] == [] and kr16["config"]["recipe"] == "default"
    assert kr16["command"].startswith("rayreach train --robot kr16 ") and "--acting-layers" not in kr16["command"]
    assert kr16["source"].endswith("best.zip")  # the checkpoint the run's validations chose


def test_shipped_kr16_policy_reaches_exp4_at_the_true_goal_size():
    _planner, record = _shipped_run("kr16", "exp4")
    assert record.outcome == "success" and not record.collision
    assert record.path_length < 1.2  # the paper's DRL path 0.91 m


def test_a_drl_model_for_the_other_robot_is_refused():
    with pytest.raises(ValueError, match="is a ur5 policy, not kr16"):
        make_planner("drl", "kr16", model=MODELS_DIR / "ur5.zip")


def test_drl_alone_runs_the_policy_without_the_acting_layers_and_the_stack_is_unchanged_after():
    """``drl-alone`` in the executor gives the episode of the paper's env stepped by the same
    policy, and the executor's next ``drl`` run is the stack's own."""
    alone = make_planner("drl-alone", "ur5")
    with Executor("exp1") as ex:
        record = ex.run(alone, seed=0)
        again = ex.run(make_planner("drl", "ur5"), seed=0)
    assert record.planner == "drl-alone" and record.config["final_approach"] is None and record.config["detour"] is None
    assert record.config["acting_layers"] == [] and record.acting_share == {"policy": 1.0}
    assert record.config["safety"] == dataclasses.asdict(ActingConfig.off().safety)
    env = ReachEnv(robot="ur5", scenario="exp1")  # the paper's env: nothing between action and arm
    try:
        obs, info = env.reset(seed=0)
        path, done = [info["ee_position"]], False
        while not done:
            obs, _, terminated, truncated, info = env.step(alone.act(obs, info))
            path.append(info["ee_position"])
            done = terminated or truncated
    finally:
        env.close()
    np.testing.assert_allclose(record.ee_path, np.asarray(path), atol=1e-9)
    assert again.config == _shipped_run("ur5", "exp1")[1].config
    np.testing.assert_allclose(again.ee_path, _shipped_run("ur5", "exp1")[1].ee_path, atol=1e-9)


def test_rollout_counts_outcomes_and_sources_per_world_kind():
    """``rollout`` on random worlds: the outcomes add up to the episodes, each kind's counts
    are those of the worlds that drew it, and the share of steps by source is that of the
    same worlds replayed one by one."""
    from collections import Counter

    from rayreach.env.episode import share
    from rayreach.evaluate.rollout import rollout
    from rayreach.scenarios.random_world import world_kinds

    summary = rollout(MODELS_DIR / "kr16.zip", "random", episodes=4, progress=False)
    assert sum(summary.outcomes.values()) == 4 and summary.outcomes["success"] == summary.successes
    assert summary.split == "validation" and summary.acting_layers == list(ActingConfig().layers)
    policy = load_policy(MODELS_DIR / "kr16.zip")
    agent = ActingPolicy(policy)
    base = ReachEnv(robot="kr16", scenario="random", goal_tolerance=0.01, observation=policy.observation)
    env = ActingEnv(base)
    base.set_n_obstacles(policy.meta["state"]["obstacles"]["count"])
    expected: dict[str, dict[str, int]] = {}
    sources: Counter = Counter()
    held: Counter = Counter()
    first = get_split("validation").start
    try:
        for episode in range(4):
            agent.reset(first + episode)
            run = run_episode(env, agent.act, first + episode)
            sources.update(run.sources)
            held.update(run.held_by)
            for kind in world_kinds(base.scenario):
                counts = expected.setdefault(kind, {"episodes": 0, "success": 0, "collision": 0,
                                                    "out_of_bounds": 0, "timeout": 0})
                counts["episodes"] += 1
                counts[run.outcome] += 1
    finally:
        env.close()
    assert summary.by_kind == dict(sorted(expected.items()))
    assert summary.acting_share == share(sources) and sum(summary.acting_share.values()) == pytest.approx(1.0)
    # every held step is told by what held it, and those shares add up to the held share
    assert sum(held.values()) == sources["held"] and set(held) <= {"shield", "arm_guard", "still"}
    assert sum(summary.held_by.values()) == pytest.approx(summary.acting_share.get("held", 0.0))


def test_batched_rollout_plays_the_worlds_rollout_plays():
    """The policy alone stepped in one ``BatchedReachEnv``: per seed the same outcome, steps
    and path as ``rollout``'s one world at a time."""
    from rayreach.evaluate.rollout import rollout, rollout_batched

    one = rollout(MODELS_DIR / "ur10.zip", "random", episodes=5, acting=ActingConfig.off(), progress=False)
    batched = rollout_batched(MODELS_DIR / "ur10.zip", episodes=5)
    for a, b in zip(one.per_episode, batched.per_episode):
        assert (a["seed"], a["outcome"], a["steps"], a["kinds"]) == (b["seed"], b["outcome"], b["steps"], b["kinds"])
        assert a["path_length"] == pytest.approx(b["path_length"], rel=1e-5)  # a batch of forward passes rounds alike, not bitwise
    assert batched.to_dict() == one.to_dict() | {"path_length_mean": batched.path_length_mean}
    with pytest.raises(ValueError, match="leave the test split"):
        rollout_batched(MODELS_DIR / "ur10.zip", episodes=2, seed=8_999_999, split="test")


def test_rollout_of_broad_worlds_counts_their_kinds_and_keeps_to_the_split():
    """Broad worlds are drawn worlds like random ones: seeds from the split, outcomes by the
    kinds ``broad_kinds`` reads, and the batched rollout plays the same worlds."""
    from rayreach.evaluate.rollout import rollout, rollout_batched
    from rayreach.scenarios.broad_world import BROAD_KINDS

    one = rollout(MODELS_DIR / "ur5.zip", "broad", episodes=2, acting=ActingConfig.off(), progress=False)
    batched = rollout_batched(MODELS_DIR / "ur5.zip", episodes=2, suite="broad")
    assert one.split == "validation" and [r["seed"] for r in one.per_episode] == [1_000_000, 1_000_001]
    assert set(one.by_kind) <= set(BROAD_KINDS) and one.by_kind
    assert all(counts["episodes"] == sum(kind in r["kinds"] for r in one.per_episode)
               for kind, counts in one.by_kind.items())
    assert [(r["outcome"], r["steps"], r["kinds"]) for r in one.per_episode] == \
        [(r["outcome"], r["steps"], r["kinds"]) for r in batched.per_episode]
    with pytest.raises(ValueError, match="leave the test split"):
        rollout(MODELS_DIR / "ur5.zip", "broad", episodes=2, seed=8_999_999, split="test", progress=False)


def test_rollout_refuses_seeds_outside_its_split():
    from rayreach.evaluate.rollout import rollout

    with pytest.raises(ValueError, match="leave the test split"):
        rollout(MODELS_DIR / "ur5.zip", "random", episodes=2, seed=8_999_999, split="test", progress=False)
    with pytest.raises(ValueError, match="unknown seed split 'train2'; valid: train, validation, test"):
        rollout(MODELS_DIR / "ur5.zip", "random", episodes=1, split="train2", progress=False)


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


def test_the_acting_policy_draws_only_where_the_arm_was_held_and_repeats_with_its_seed():
    policy = load_policy(MODELS_DIR / "ur5.zip")
    obs = _exp1_start_observation()
    moved, held = {"acting": {"source": "policy", "held": False}}, {"acting": {"source": "held", "held": True}}
    acting = ActingPolicy(policy)

    def run(seed: int) -> list[np.ndarray]:
        acting.reset(seed)
        return [acting.act(obs, info) for info in ({}, moved, held, held, moved)]

    actions = run(3)
    for i in (0, 1, 4):  # the arm moved (or the episode starts): the mean
        np.testing.assert_array_equal(actions[i], policy.act(obs, deterministic=True))
    assert not np.allclose(actions[2], actions[1]) and not np.allclose(actions[3], actions[2])  # drawn, and anew
    np.testing.assert_array_equal(np.array(run(3)), np.array(actions))
    assert not np.allclose(run(4)[2], actions[2])
    bare = ActingPolicy(policy, resample=False)
    bare.reset(3)
    np.testing.assert_array_equal(bare.act(obs, held), policy.act(obs, deterministic=True))


def test_a_held_draw_is_at_least_as_wide_as_the_floor_and_the_shipped_policies_draw_as_before():
    """``least_std`` widens only the dimensions whose noise lies below it: against the
    policy's own mean, draws at least 3.0 wide spread farther than the policy's own and
    land mostly on a bound of [-1, 1]; the shipped UR5's noise lies above ``HELD_DRAW_STD`` in every
    dimension, so its held draws repeat those without a floor, draw for draw."""
    from rayreach.acting.resample import HELD_DRAW_STD

    policy = load_policy(MODELS_DIR / "ur5.zip")
    obs = _exp1_start_observation()
    assert np.exp(policy.model.policy.log_std.detach().numpy()).min() > HELD_DRAW_STD
    plain = [policy.sample(obs, np.random.default_rng(i)) for i in range(50)]
    floored = [policy.sample(obs, np.random.default_rng(i), HELD_DRAW_STD) for i in range(50)]
    np.testing.assert_array_equal(np.array(plain), np.array(floored))
    mean = policy.act(obs, deterministic=True)
    rng = np.random.default_rng(0)
    wide = np.array([policy.sample(obs, rng, 3.0) for _ in range(2000)])
    narrow = np.array([policy.sample(obs, rng) for _ in range(2000)])
    assert np.all(np.abs(wide) <= 1.0)
    assert np.all(np.abs(wide - mean).mean(axis=0) > np.abs(narrow - mean).mean(axis=0))
    assert np.all((np.abs(wide) > 0.999).mean(axis=0) > 0.5)  # a deviation of 3 mostly lands on a bound


@pytest.mark.expensive
@pytest.mark.parametrize("scenario", EXPERIMENTS)
def test_the_shipped_stack_solves_every_experiment_within_the_papers_path(scenario):
    """Thirty runs of each experiment with every acting layer: all succeed, the mean path at
    or below the paper's DRL path (``docs/results.md``; ``make test-all``)."""
    paper = {"exp1": 0.45, "exp2": 0.85, "exp3": 1.18, "exp4": 0.91, "exp5": 0.93, "exp6": 0.95, "exp7": 0.98}
    with Executor(scenario) as ex:
        planner = make_planner("drl", ex.robot)
        records = [ex.run(planner, seed) for seed in range(30)]
    assert all(r.success for r in records)
    assert np.mean([r.path_length for r in records]) <= paper[scenario]
