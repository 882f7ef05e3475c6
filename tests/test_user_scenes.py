"""A user's scenes: many IK seeds for a goal that a table or box crowds, and the DRL planner
refusing starts and goals outside the workspace its policy was trained in."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from rayreach.evaluate.executor import ExecutionConfig, Executor
from rayreach.planners import Status, make_planner
from rayreach.planners.drl import DRLPlanner
from rayreach.scenarios.schema import StartSpec

CROWDED_WORLD = 1_000_000
"""A UR5 broad world (validation split) whose goal, behind the robot, is crowded by its scene:
started from the home configuration instead of the world's own start, the start-seeded IK
solution and all 16 first random seeds' solutions collide (today's count: goal in collision),
while the further seeds find a free one. Found by trying broad worlds from 1,000,000 on."""


@pytest.fixture(scope="module")
def crowded():
    """The world's obstacles and goal with the arm starting at home."""
    with Executor("broad", robot="ur5") as ex:
        ex.reset(CROWDED_WORLD)
        home = tuple(float(v) for v in ex.spec.home)
        return replace(ex.env.scenario, name="crowded", start=StartSpec(joints=home))


@pytest.fixture(scope="module")
def policies():
    return {robot: DRLPlanner(robot) for robot in ("ur5", "kr16")}


def test_more_ik_seeds_find_a_free_goal_where_the_first_seeds_collide(crowded):
    with Executor(crowded, config=ExecutionConfig(goal_ik_more_seeds=0)) as old:
        old.reset(0)
        goals, bad, message = old.goal_configurations(0)
        assert goals == [] and bad is Status.GOAL_IN_COLLISION and "goal in collision" in message
    with Executor(crowded) as new:
        new.reset(0)
        goals, bad, _ = new.goal_configurations(0)
        assert bad is None and len(goals) == 1
        assert new.checker.valid(goals[0])
        assert np.linalg.norm(new.kin.fk(goals[0])[:3, 3] - np.asarray(crowded.goals[0])) < 1e-3
        again, _, _ = new.goal_configurations(0)  # every planner of run 0 gets this goal
        np.testing.assert_array_equal(again[0], goals[0])
        other, _, _ = new.goal_configurations(1)
        assert other  # another run's seeds also find one (not necessarily the same)


def test_the_further_seeds_leave_goals_the_first_seeds_solve_unchanged():
    with Executor("broad", robot="ur5", config=ExecutionConfig(goal_ik_more_seeds=0)) as old, \
            Executor("broad", robot="ur5") as new:
        for seed in (1_000_001, 1_000_002):
            old.reset(seed)
            new.reset(seed)
            np.testing.assert_array_equal(old.goal_configurations(seed)[0][0], new.goal_configurations(seed)[0][0])


def test_drl_refuses_a_scene_outside_its_training_workspace(crowded, policies):
    planner = policies["ur5"]
    with Executor(crowded) as ex:
        record = ex.run(planner, 0)
    assert record.outcome == Status.OUTSIDE_TRAINING.value == record.plan_status
    assert not record.success and record.steps == 0
    message = record.message
    assert "goal 0" in message and "training workspace" in message and "[-0.4, 0.3, 0.2] .. [0.4, 0.7, 0.5]" in message
    assert "sampling planner" in message and "refuse_unseen=False" in message
    allowed = DRLPlanner("ur5", refuse_unseen=False)
    assert allowed.refusal(ex.env.ee_pos, ex.env.goals) is None
    assert make_planner("drl", "ur5", refuse_unseen=False).refusal(ex.env.ee_pos, ex.env.goals) is None
    assert make_planner("drl", "ur5").refusal(ex.env.ee_pos, ex.env.goals) == message


def test_drl_refuses_broad_worlds_outside_the_box_and_accepts_the_paper_and_random_worlds(policies):
    for name in [f"exp{i}" for i in range(1, 8)]:
        with Executor(name) as ex:
            ex.reset(0)
            assert policies[ex.robot].refusal(ex.env.ee_pos, ex.env.goals) is None, name
    for robot in ("ur5", "kr16"):
        with Executor("random", robot=robot) as ex:
            for seed in range(1_000_000, 1_000_010):
                ex.reset(seed)
                assert policies[robot].refusal(ex.env.ee_pos, ex.env.goals) is None, (robot, seed)
        with Executor("broad", robot=robot) as ex:
            refused = 0
            for seed in range(1_000_000, 1_000_010):
                ex.reset(seed)
                refused += policies[robot].refusal(ex.env.ee_pos, ex.env.goals) is not None
            assert refused >= 5, robot  # the broad worlds reach well beyond the training box
