"""The goal rays (``rayreach.sim.goal_rays``): three rays parallel to goal minus tip, from the
tip, the tool's middle and the flange, as long as the tip is from the goal. Measured on a
constructed scene against the plate's geometry and PyBullet's own ray test."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from rayreach.env.batched import BatchedReachEnv
from rayreach.env.observation import ObservationConfig
from rayreach.env.reach import ReachEnv
from rayreach.sim.goal_rays import N_GOAL_RAYS, SHORTEST, goal_rays
from scenes import wall_before_the_goal

SIGHT = replace(ObservationConfig.planner(), goal_sight=True)
WALL_AT = 0.1
"""How far out from the tip the wall's near face stands, m."""
GOAL_OUT = 0.2
"""How far out from the tip the goal lies, m."""


def test_the_rays_start_along_the_tool_and_run_parallel_to_the_goal_offset():
    tip = np.array([[0.4, 0.1, 0.3], [0.0, 0.0, 0.5]])
    tool = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    goal = np.array([[0.4, 0.4, 0.7], [0.0, 0.0, 0.5]])  # the second: at the goal
    origins, directions, lengths = goal_rays(tip, tool, goal, 0.13)
    assert origins.shape == directions.shape == (2, N_GOAL_RAYS, 3)
    np.testing.assert_allclose(origins[0], [[0.4, 0.1, 0.3], [0.4, 0.1, 0.365], [0.4, 0.1, 0.43]])
    np.testing.assert_allclose(directions[0], np.tile([0.0, 0.6, 0.8], (3, 1)))
    assert lengths[0] == pytest.approx(0.5)
    np.testing.assert_allclose(directions[1], np.tile(tool[1], (3, 1)))  # at the goal: along the tool
    assert lengths[1] == SHORTEST


@pytest.mark.parametrize("reach_up, expected", [
    (0.03, (WALL_AT / GOAL_OUT, 1.0, 1.0)),  # the wall stands by the tip only
    (0.1, (WALL_AT / GOAL_OUT, WALL_AT / GOAL_OUT, 1.0)),  # up to the tool's middle (0.065 m), not the flange (0.13)
    (0.2, (WALL_AT / GOAL_OUT,) * 3),
])
@pytest.mark.parametrize("backend", ["bullet", "numpy"])
def test_a_wall_before_the_goal_reads_where_it_stands_on_each_ray_that_meets_it(reach_up, expected, backend):
    env = ReachEnv(scenario=wall_before_the_goal(WALL_AT, GOAL_OUT, reach_up), observation=SIGHT, ray_backend=backend)
    try:
        obs, _ = env.reset(seed=0)
        np.testing.assert_allclose(obs[-N_GOAL_RAYS:], expected, atol=2e-3)
    finally:
        env.close()


def test_the_batched_env_reads_the_goal_rays_as_reach_env_does_with_pybullet():
    scenario = wall_before_the_goal(WALL_AT, GOAL_OUT, 0.1)
    single = ReachEnv(scenario=scenario, observation=SIGHT, ray_backend="bullet")
    batched = BatchedReachEnv(None, 2, scenario, observation=SIGHT, seed=0)
    try:
        reference, _ = single.reset(seed=0)
        obs = batched.reset()
        np.testing.assert_allclose(obs[:, -N_GOAL_RAYS:], np.tile(reference[-N_GOAL_RAYS:], (2, 1)), atol=1e-4)
        action = np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0], dtype=np.float32)  # the rays follow the tool
        for _ in range(5):
            reference = single.step(action)[0]
            obs = batched.step(np.tile(action, (2, 1)))[0]
        np.testing.assert_allclose(obs[0, -N_GOAL_RAYS:], reference[-N_GOAL_RAYS:], atol=1e-4)
    finally:
        single.close()
        batched.close()


def test_an_observation_without_the_goal_rays_is_refused_them():
    from rayreach.env.observation import OBS_SIZE, Observer

    observer = Observer(replace(ObservationConfig(), goal_sight=True), 1, 129, OBS_SIZE, 0.005)
    assert observer.size == OBS_SIZE + N_GOAL_RAYS
    args = (np.array([0]), np.zeros((1, OBS_SIZE)), np.zeros((1, 3)), np.ones((1, 129)), np.zeros((1, 3)),
            np.ones((1, 3)))
    with pytest.raises(ValueError, match="goal rays"):
        observer.reset(*args)
