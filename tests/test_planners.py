"""Sampling planners: solve, detour, determinism, distinct failure statuses, re-checked paths."""

from __future__ import annotations

import numpy as np
import pytest

from rayreach.env.reach import ReachEnv
from rayreach.planners import make_planner
from rayreach.planners.collision import CollisionChecker
from rayreach.planners.ncrrt import NCRRTConfig, ncrrt
from rayreach.planners.ompl_peer import OMPLConfig, ompl_available, ompl_plan
from rayreach.planners.result import Status
from rayreach.planners.rrt import RRTConfig, birrt, rrt
from rayreach.planners.smoothing import path_length, shortcut
from rayreach.scenarios.feasibility import goal_configuration
from rayreach.scenarios.schema import ObstacleSpec

FAST = RRTConfig(time_limit=20.0)
needs_ompl = pytest.mark.skipif(not ompl_available(), reason="OMPL not installed (pip install rayreach[ompl])")
ALL = [
    pytest.param("rrt", lambda s, g, c, r: rrt(s, g, c, r, FAST), id="rrt"),
    pytest.param("birrt", lambda s, g, c, r: birrt(s, g, c, r, FAST), id="birrt"),
    pytest.param("ncrrt", lambda s, g, c, r: ncrrt(s, g, c, r, NCRRTConfig(time_limit=20.0)), id="ncrrt"),
    pytest.param("ompl-rrt", lambda s, g, c, r: ompl_plan(s, g, c, r, OMPLConfig("RRT", time_limit=20.0)),
                 marks=needs_ompl, id="ompl-rrt"),
    pytest.param("ompl-rrtconnect", lambda s, g, c, r: ompl_plan(s, g, c, r, OMPLConfig(time_limit=20.0)),
                 marks=needs_ompl, id="ompl-rrtconnect"),
]


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


@pytest.mark.parametrize("name,plan", ALL)
def test_plans_around_the_plate_and_path_is_valid_at_4x_resolution(exp1, name, plan):
    env, checker, q_start, q_goal = exp1
    assert _segment_collides(checker, q_start, q_goal, FAST.resolution)  # the direct move is blocked
    result = plan(q_start, q_goal, checker, np.random.default_rng(3))
    assert result.status is Status.SOLVED, result.message
    path = np.asarray(result.path)
    np.testing.assert_array_equal(path[0], q_start)
    np.testing.assert_array_equal(path[-1], q_goal)
    for qa, qb in zip(path[:-1], path[1:]):
        assert not _segment_collides(checker, qa, qb, FAST.resolution / 4)
    assert result.config["planner"] == name and result.config["time_limit"] == 20.0
    assert result.joint_path_length > np.linalg.norm(q_goal - q_start)  # a detour


@pytest.mark.parametrize("name,plan", ALL)
def test_identical_seeds_give_identical_paths(exp1, name, plan):
    _, checker, q_start, q_goal = exp1
    a = plan(q_start, q_goal, checker, np.random.default_rng(11))
    b = plan(q_start, q_goal, checker, np.random.default_rng(11))
    assert a.solved and b.solved
    np.testing.assert_array_equal(np.asarray(a.path), np.asarray(b.path))


@pytest.mark.parametrize("name,plan", ALL)
def test_goal_in_collision_and_invalid_start_are_reported_not_searched(exp1, name, plan):
    env, checker, q_start, q_goal = exp1
    blocker = ObstacleSpec("sphere", tuple(env.kin.fk(q_goal)[:3, 3]), radius=0.05)
    env.scene.set_obstacles([*env.scenario.obstacles, blocker])
    try:
        result = plan(q_start, q_goal, checker, np.random.default_rng(0))
        assert result.status is Status.GOAL_IN_COLLISION and result.path is None and result.planning_time < 1.0
        result = plan(q_goal, q_start, checker, np.random.default_rng(0))
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


def test_nc_rrt_node_control_excludes_nodes_that_keep_failing():
    from rayreach.planners.ncrrt import ControlledTree

    tree = ControlledTree(np.zeros(6), capacity=2)
    for i in range(4):  # grows past its capacity
        tree.add(np.full(6, i + 1.0), i)
    tree.failures[1] = 3
    allowed = tree.allowed(3)
    assert allowed.tolist() == [True, False, True, True, True]
    assert tree.nearest(np.full(6, 1.0), allowed) != 1  # node 1 is the closest but excluded
    assert tree.nearest(np.full(6, 1.0)) == 1


def test_nc_rrt_sampling_ball_stays_in_ball_and_box():
    from rayreach.planners.ncrrt import SamplingBall

    rng = np.random.default_rng(0)
    low, high = -np.ones(6), np.ones(6)
    for radius in (0.3, 5.0):
        ball = SamplingBall(np.full(6, 0.5), radius, low, high)
        samples = np.array([ball.sample(rng) for _ in range(300)])
        assert np.all(samples >= low) and np.all(samples <= high)
        assert np.all(np.linalg.norm(samples - ball.centre, axis=1) <= radius + 1e-12)


def test_shortcut_never_lengthens_and_keeps_ends_and_validity(exp1):
    _, checker, q_start, q_goal = exp1
    result = rrt(q_start, q_goal, checker, np.random.default_rng(1), FAST)
    assert result.solved
    smooth = shortcut(result.path, checker, np.random.default_rng(0))
    assert path_length(smooth) <= path_length(result.path)
    np.testing.assert_array_equal(smooth[0], q_start)
    np.testing.assert_array_equal(smooth[-1], q_goal)
    for qa, qb in zip(smooth[:-1], smooth[1:]):
        assert not _segment_collides(checker, qa, qb, FAST.resolution / 4)


def test_smoothing_planner_keeps_the_raw_path_and_full_config(exp1):
    _, checker, q_start, q_goal = exp1
    planner = make_planner("rrt", "ur5", time_limit=20.0, smooth=True)
    result = planner.plan(checker, q_start, q_goal, np.random.default_rng(1))
    assert result.solved and result.raw_path is not None
    assert result.joint_path_length < path_length(result.raw_path)
    assert result.config["smoothing"]["attempts"] > 0 and result.config["goal_bias"] == 0.35


def test_unknown_planner_names_the_valid_ones():
    with pytest.raises(ValueError, match="ncrrt.*ompl-rrtconnect"):
        make_planner("prm", "ur5")
