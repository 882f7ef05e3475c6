"""Sampling planners: solve, detour, determinism, distinct failure statuses, re-checked paths."""

from __future__ import annotations

import numpy as np
import pytest

from rayreach.env import ReachEnv
from rayreach.planners.collision import CollisionChecker
from rayreach.planners.result import Status
from rayreach.planners.rrt import RRTConfig, birrt, rrt
from rayreach.scenarios.feasibility import goal_configuration
from rayreach.scenarios.schema import ObstacleSpec

PLANNERS = {"rrt": rrt, "birrt": birrt}
FAST = RRTConfig(time_limit=20.0)


@pytest.fixture(scope="module")
def exp1():
    env = ReachEnv(scenario="exp1")
    env.reset(seed=0)
    q_goal = goal_configuration(env.kin, env.goals[0], env.q, np.random.default_rng(0))
    assert q_goal is not None
    yield env, CollisionChecker(env.scene), env.q.copy(), q_goal
    env.close()


def _segment_collides(checker: CollisionChecker, qa, qb, resolution: float) -> bool:
    n = int(np.ceil(np.max(np.abs(qb - qa)) / resolution))
    return any(not checker.valid(qa + (qb - qa) * i / n) for i in range(n + 1))


@pytest.mark.parametrize("name", PLANNERS)
def test_plans_around_the_plate_and_path_is_valid_at_4x_resolution(exp1, name):
    env, checker, q_start, q_goal = exp1
    assert _segment_collides(checker, q_start, q_goal, FAST.resolution)  # the direct move is blocked
    result = PLANNERS[name](q_start, q_goal, checker, np.random.default_rng(3), FAST)
    assert result.status is Status.SOLVED, result.message
    path = np.asarray(result.path)
    np.testing.assert_array_equal(path[0], q_start)
    np.testing.assert_array_equal(path[-1], q_goal)
    for qa, qb in zip(path[:-1], path[1:]):
        assert not _segment_collides(checker, qa, qb, FAST.resolution / 4)
    assert result.config["planner"] == name and result.config["step_size"] == FAST.step_size
    assert result.joint_path_length > np.linalg.norm(q_goal - q_start)  # a detour


@pytest.mark.parametrize("name", PLANNERS)
def test_identical_seeds_give_identical_paths(exp1, name):
    _, checker, q_start, q_goal = exp1
    a = PLANNERS[name](q_start, q_goal, checker, np.random.default_rng(11), FAST)
    b = PLANNERS[name](q_start, q_goal, checker, np.random.default_rng(11), FAST)
    assert a.solved and b.solved
    np.testing.assert_array_equal(np.asarray(a.path), np.asarray(b.path))


@pytest.mark.parametrize("name", PLANNERS)
def test_goal_in_collision_and_invalid_start_are_reported_not_searched(exp1, name):
    env, checker, q_start, q_goal = exp1
    blocker = ObstacleSpec("sphere", tuple(env.kin.fk(q_goal)[:3, 3]), radius=0.05)
    env.scene.set_obstacles([*env.scenario.obstacles, blocker])
    try:
        result = PLANNERS[name](q_start, q_goal, checker, np.random.default_rng(0), FAST)
        assert result.status is Status.GOAL_IN_COLLISION and result.path is None and result.planning_time < 1.0
        result = PLANNERS[name](q_goal, q_start, checker, np.random.default_rng(0), FAST)
        assert result.status is Status.INVALID_START and result.path is None
    finally:
        env.scene.set_obstacles(env.scenario.obstacles)


def test_timeout_is_a_status_with_no_path(exp1):
    _, checker, q_start, q_goal = exp1
    result = rrt(q_start, q_goal, checker, np.random.default_rng(0), RRTConfig(goal_bias=0.0, time_limit=0.05))
    assert result.status is Status.TIMEOUT and result.path is None and "0.05" in result.message


def test_checker_counts_and_respects_joint_limits(exp1):
    _, checker, q_start, _ = exp1
    before = checker.checks
    assert checker.valid(q_start)
    outside = q_start.copy()
    outside[2] = checker.upper[2] + 0.1
    assert not checker.valid(outside)
    assert checker.checks == before + 2
