"""The executor: speed limits, collision at every step, shared goal configurations, both
planner kinds, failure statuses and the replanning mode."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from rayreach.evaluate.executor import ExecutionConfig, Executor, time_path
from rayreach.planners import ReactivePlanner, Status, make_planner
from rayreach.scenarios import get_scenario
from rayreach.scenarios.schema import ObstacleSpec

PERIOD = 1.0 / 240.0


@pytest.fixture(scope="module")
def exp1():
    with Executor("exp1") as ex:
        yield ex


def test_timed_path_respects_the_speed_limits_and_hits_every_waypoint(exp1):
    ex = exp1
    q0 = ex.reset(0)
    path = [q0, q0 + np.array([0.6, -0.3, 0.2, 0.0, 0.5, -1.0]), q0 + np.array([0.1, 0.1, 0.1, 0.1, 0.1, 0.1])]
    velocity = np.asarray(ex.spec.velocity)
    qs, ees = time_path(ex.kin, path, velocity, PERIOD, ex.spec.ee_step)
    steps = np.abs(np.diff(qs, axis=0))
    assert np.all(steps <= velocity * PERIOD + 1e-12)
    # the end-effector positions agree with PyBullet's own kinematics, and no step exceeds 5 mm
    for i in range(0, len(qs), max(1, len(qs) // 20)):
        ex.scene.set_joints(qs[i])
        np.testing.assert_allclose(ex.scene.tcp_pose()[0], ees[i], atol=1e-6)
    assert np.max(np.abs(np.diff(ees, axis=0))) <= ex.spec.ee_step + 1e-12  # the DRL action's per-axis bound
    for waypoint in path:
        assert any(np.array_equal(q, waypoint) for q in qs)
    np.testing.assert_array_equal(qs[-1], path[-1])


def test_a_global_planner_run_is_measured_and_collision_free_at_every_step(exp1):
    ex = exp1
    record = ex.run(make_planner("birrt", "ur5"), seed=0)
    assert record.outcome == "success" and record.success and not record.collision, record.message
    assert record.steps == len(record.ee_path) - 1 == len(record.joint_path) - 1
    assert record.motion_time == pytest.approx(record.steps * PERIOD)
    assert record.execution_time == pytest.approx(record.planning_time + record.motion_time)
    goal = np.asarray(get_scenario("exp1").goals[0])
    assert np.linalg.norm(record.ee_path[-1] - goal) < 1e-3
    assert record.path_length > np.linalg.norm(record.ee_path[0] - goal)  # around the plate
    assert record.path_length == pytest.approx(np.linalg.norm(np.diff(record.ee_path, axis=0), axis=1).sum())
    ex.scene.set_time(0.0)
    assert all(ex.checker.valid(q) for q in record.joint_path)
    assert record.config["planner"] == "birrt" and record.config["resolution"] == 0.02


def test_every_planner_of_a_run_gets_the_same_goal_configuration(exp1):
    ex = exp1
    ex.reset(3)
    a, bad_a, _ = ex.goal_configurations(3)
    b, bad_b, _ = ex.goal_configurations(3)
    assert bad_a is None and bad_b is None
    np.testing.assert_array_equal(a[0], b[0])
    assert ex.checker.valid(a[0])
    runs = [ex.run(make_planner(name, "ur5"), seed=3) for name in ("birrt", "ncrrt")]
    for run in runs:
        np.testing.assert_array_equal(run.joint_path[-1], a[0])


def test_unreachable_goal_and_goal_inside_an_obstacle_are_statuses_not_hangs(exp1):
    ex = exp1
    q0 = ex.reset(0)
    _, status = ex.goal_configuration(np.array([3.0, 0.0, 0.5]), q0, np.random.default_rng(0))
    assert status is Status.GOAL_UNREACHABLE
    goal = get_scenario("exp1").goals[0]
    blocked = dataclasses.replace(get_scenario("exp1"), obstacles=(ObstacleSpec("sphere", goal, radius=0.06),))
    with Executor(blocked) as ex2:
        record = ex2.run(make_planner("rrt", "ur5"), seed=0)
    assert record.outcome == "no plan" and record.plan_status == "goal in collision"
    assert "goal 0" in record.message and record.planning_time < 5.0 and np.isnan(record.path_length)


def _crossing_scenario():
    """exp1 plus a sphere sweeping back and forth over the plate, across the paths around it."""
    base = get_scenario("exp1")
    return dataclasses.replace(base, obstacles=base.obstacles + (
        ObstacleSpec("sphere", (0.0, 0.1, 0.36), radius=0.05, velocity=(0.0, 0.6, 0.0), travel=0.5,
                     name="intruder"),))


def test_plan_once_collides_with_a_moving_obstacle_and_replanning_reacts():
    scenario = _crossing_scenario()
    outcomes = {}
    for replan in (False, True):
        with Executor(scenario, config=ExecutionConfig(replan=replan)) as ex:
            runs = [ex.run(make_planner("birrt", "ur5"), seed) for seed in range(6)]
        outcomes[replan] = runs
    assert any(r.collision for r in outcomes[False])
    assert all(r.replans == 0 for r in outcomes[False])
    assert any(r.replans > 0 for r in outcomes[True])
    assert sum(r.collision for r in outcomes[True]) < sum(r.collision for r in outcomes[False])


class StraightToGoal(ReactivePlanner):
    """A reactive stand-in for the policy: full steps towards the goal."""

    name = "straight"

    def __init__(self) -> None:
        self.seeds: list[int] = []

    def reset(self, seed: int) -> None:
        self.seeds.append(seed)

    def act(self, observation: np.ndarray, info: dict) -> np.ndarray:
        offset = observation[6:9]
        return np.concatenate((np.clip(offset / 0.005, -1, 1), np.zeros(3))).astype(np.float32)

    def config(self) -> dict:
        return {"planner": self.name}


def test_a_reactive_planner_runs_through_the_env_and_is_measured_alike():
    scenario = dataclasses.replace(get_scenario("exp1"), obstacles=())
    planner = StraightToGoal()
    with Executor(scenario) as ex:
        record = ex.run(planner, seed=0)
        ex.run(planner, seed=7)
    assert planner.seeds == [0, 7]  # each run starts the planner with its seed
    assert record.outcome == "success" and record.plan_status == "solved"
    assert record.planning_time > 0 and record.motion_time == pytest.approx(record.steps * PERIOD)
    assert record.path_length == pytest.approx(0.3, abs=0.02)  # start and goal are 0.3 m apart
    assert record.steps == pytest.approx(0.3 / 0.005, abs=3)  # 0.3 m along x at 5 mm per step


def test_two_goals_are_visited_in_order():
    with Executor("exp2") as ex:
        record = ex.run(make_planner("ncrrt", "ur5"), seed=0)
    goals = np.asarray(get_scenario("exp2").goals)
    assert record.success, record.message
    first = int(np.argmin(np.linalg.norm(record.ee_path - goals[0], axis=1)))
    assert np.linalg.norm(record.ee_path[first] - goals[0]) < 1e-3
    assert np.linalg.norm(record.ee_path[-1] - goals[1]) < 1e-3 and first < len(record.ee_path) - 1


def test_bench_planners_prints_one_json_line_with_checks_per_second(capsys):
    import json

    from rayreach.cli import main

    assert main(["bench-planners", "--scenario", "exp1", "--runs", "2", "--planners", "birrt,ncrrt", "--json"]) == 0
    record = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert record["checks_per_s"] > 1000
    assert set(record["planners"]) == {"birrt", "ncrrt"}
    assert record["planners"]["ncrrt"]["solved"] == 2 and record["planners"]["ncrrt"]["path_length_median_m"] > 0.3
