"""The fixed task of the recipe comparison holds both curricula; its clock ends training."""

from __future__ import annotations

import json

import pytest

from rayreach.evaluate.compare_recipes import GOAL, OBSTACLES, WallClock, fixed_task
from rayreach.learning.curriculum import AugmentedGoalSize, ObstacleCurriculum
from rayreach.learning.train import env_config, recipe


@pytest.mark.parametrize("name", ["baseline", "default"])
def test_the_fixed_task_keeps_goal_and_obstacles_whatever_the_outcomes(name):
    config = fixed_task(recipe(name))
    goal, obstacles = AugmentedGoalSize(config.goal), ObstacleCurriculum(config.obstacles)
    for episode in range(3000):  # long runs of failures, then of successes
        success = episode >= 1500
        goal.record(success)
        obstacles.record(success, at_true_size=True)
        assert goal.size == GOAL and obstacles.count == OBSTACLES
    assert config.true_goal_share == 0.0
    assert (config.envs, config.batch_size) == (recipe(name).envs, recipe(name).batch_size)


def test_variants_change_one_thing_of_their_recipe():
    from dataclasses import fields

    from rayreach.cli import COMPARE_VARIANTS
    from rayreach.evaluate.compare_recipes import VARIANTS, variant

    assert COMPARE_VARIANTS == tuple(VARIANTS)  # the CLI names them without importing torch
    default = recipe("default", robot="kr16")
    for name in ("paper-observation", "no-scans", "long-scans", "sightings", "no-workspace", "entropy", "around-obstacles", "proximity",
                 "collision-20", "collision-40", "slow-covers", "separate-features", "wide", "decide-1", "decide-2",
                 "decide-8"):
        changed = [f.name for f in fields(default) if getattr(variant(name, "kr16"), f.name) != getattr(default, f.name)]
        assert len(changed) == 1, (name, changed)
    long = variant("long-scans", "ur5").observation  # four scans reaching 96 steps back
    assert (long.scans, long.scans * long.scan_stride) == (4, 96)
    sight = variant("sightings", "ur5").observation  # twelve windows of eight steps: 0.4 s
    assert (sight.sightings, sight.sightings * sight.sighting_window, sight.scans) == (12, 96, 3)
    assert variant("no-scans", "ur5").observation.scans == 0 and variant("paper-observation", "ur5").observation.is_paper
    # the tip-back rays are in the UR5's default and out of the KR16's; each variant sets them for both robots
    assert recipe("default", robot="ur5").observation.tip_back and not default.observation.tip_back
    for robot in ("ur5", "kr16"):
        assert variant("tip-back", robot).observation.tip_back and not variant("no-tip-back", robot).observation.tip_back
    # an observation variant changes its named fields of each robot's own default and no other
    for robot in ("ur5", "kr16"):
        own = recipe("default", robot=robot).observation
        for name, named in (("slanted", {"slanted"}), ("goal-sight", {"goal_sight"}), ("sightings", {"sightings"}),
                            ("long-scans", {"scans", "scan_stride"}), ("no-workspace", {"workspace"})):
            seen = variant(name, robot).observation
            assert {f.name for f in fields(own) if getattr(seen, f.name) != getattr(own, f.name)} == named, (robot, name)
    for name, weight in (("collision-20", -20.0), ("collision-40", -40.0)):  # the weight reaches the reward
        assert env_config(variant(name, "ur5")).rewards.collision == weight
    assert env_config(default).rewards.collision == -10.0  # the paper's r_c
    assert not variant("separate-features", "ur5").share_features and variant("wide", "ur5").features == (512, 512)
    task = fixed_task(variant("entropy", "ur5"), goal=0.01, obstacles=2)
    assert (task.goal.rho, task.obstacles.start, task.ent_coef) == (0.01, 2, 0.005)
    with pytest.raises(ValueError, match="paper-observation"):
        variant("bigger", "ur5")


def test_the_wall_clock_stops_learning():
    from stable_baselines3 import PPO

    from rayreach.env.batched import BatchedReachEnv

    env = BatchedReachEnv("ur5", 2, seed=0, max_steps=20)
    try:
        model = PPO("MlpPolicy", env, n_steps=8, batch_size=16, n_epochs=1)
        model.learn(10**9, callback=WallClock(1.0))
        assert 0 < model.num_timesteps < 10**9
    finally:
        env.close()


@pytest.mark.expensive
def test_compare_recipes_writes_curves_and_a_summary(tmp_path):
    from rayreach.cli import main

    assert main(["compare-recipes", "--robot", "ur5", "--minutes", "0.2", "--episodes", "2",
                 "--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert set(summary["recipes"]) == {"baseline", "default"} and (tmp_path / "curves.png").exists()
    assert all(r["validation"]["success_rate"] is not None for r in summary["recipes"].values())
