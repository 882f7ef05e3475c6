"""``rayreach.plan``: one query through the executor, with paths a user can take as they are."""

from __future__ import annotations

import functools
import json
import math

import numpy as np
import pytest

import rayreach
from rayreach.api import as_scenario
from rayreach.evaluate.executor import RunRecord, polyline_length
from rayreach.planners import PLANNER_NAMES
from rayreach.robots import get_robot
from rayreach.scenarios import ObstacleSpec, ScenarioError, builtin_path, get_scenario
from rayreach.sim.kinematics import Kinematics

QUERIES = {"drl": dict(seed=0, model="ur5"), "rrt": dict(seed=3, time_limit=10.0)}
"""exp1 queries: the shipped policy by name; RRT with a seed that plans in milliseconds."""


@functools.cache
def _planned(planner: str) -> rayreach.PlanOutcome:
    """Each planner's exp1 query once per module: the tests below read the same outcome."""
    return rayreach.plan("exp1", planner=planner, **QUERIES[planner])


def _exp1() -> dict:
    return json.loads(builtin_path("exp1").read_text())


@pytest.mark.parametrize("planner", sorted(QUERIES))
def test_plan_exp1_returns_the_executed_path(planner):
    outcome = _planned(planner)
    assert outcome.status == "success" and outcome.success and outcome.status in rayreach.STATUSES
    assert isinstance(outcome.record, RunRecord) and outcome.record.planner == planner
    n = len(outcome.times)
    assert n > 10 and outcome.joint_path.shape == (n, 6) and outcome.ee_path.shape == (n, 3)
    period = np.diff(outcome.times)
    assert outcome.times[0] == 0.0 and np.all(period > 0) and np.allclose(period, period[0])
    assert outcome.times[-1] == pytest.approx(outcome.record.motion_time)
    assert abs(outcome.path_length - polyline_length(outcome.ee_path)) < 1e-9
    scene = get_scenario("exp1")
    assert np.linalg.norm(outcome.ee_path[0] - scene.start.position) < 0.01
    assert np.linalg.norm(outcome.ee_path[-1] - scene.goals[-1]) < 0.01
    kin = Kinematics(get_robot("ur5"))  # rows pair up: each tool position is its joint row's
    for i in (0, n // 2, n - 1):
        assert np.allclose(kin.fk(outcome.joint_path[i])[:3, 3], outcome.ee_path[i], atol=1e-6)
    assert outcome.planning_time > 0


def test_plan_takes_a_dict_with_the_scene_files_fields():
    data = _exp1()
    data["name"] = "exp1-as-dict"
    outcome = rayreach.plan(data, planner="ncrrt", seed=0)
    assert outcome.status == "success" and outcome.record.scenario == "exp1-as-dict"


def test_no_plan_has_empty_paths_and_says_why():
    data = _exp1()  # the goal inside a box: no collision-free goal configuration
    data["obstacles"].append({"shape": "box", "position": data["goals"][0], "half_extents": [0.04] * 3})
    outcome = rayreach.plan(data, planner="ncrrt", seed=0)
    assert outcome.status == "no plan" and not outcome.success
    assert outcome.record.plan_status == "goal in collision" and "goal 0" in outcome.record.message
    assert outcome.joint_path.shape == (0, 6) and outcome.ee_path.shape == (0, 3) and len(outcome.times) == 0
    assert math.isnan(outcome.path_length)


@pytest.mark.parametrize("change,field", [
    (lambda d: d.pop("goals"), "missing field 'goals'"),
    (lambda d: d["obstacles"][0].pop("half_extents"), "obstacles[0].half_extents: missing"),
    (lambda d: d.update(robot="ur3"), "unknown robot 'ur3'; known: kr16, ur10, ur5"),
])
def test_a_bad_dict_gives_the_scene_files_message(tmp_path, change, field):
    data = _exp1()
    change(data)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ScenarioError) as from_file:
        get_scenario(path)
    with pytest.raises(ScenarioError) as from_dict:
        rayreach.plan(data, planner="ncrrt")
    assert field in str(from_dict.value)
    assert str(from_dict.value) == str(from_file.value).replace("bad.json", "scene", 1)


def test_unknown_planner_and_scene_name_the_valid_ones():
    with pytest.raises(ValueError, match="unknown planner 'rrt-star'; valid: drl, drl-alone") as bad:
        rayreach.plan("exp1", planner="rrt-star")
    assert all(name in str(bad.value) for name in PLANNER_NAMES)
    with pytest.raises(ScenarioError, match="unknown scenario 'exp9'; known: exp1, exp2.*exp7.*path"):
        rayreach.plan("exp9")
    with pytest.raises(TypeError, match="scene: expected a name"):
        rayreach.plan(42)


def test_a_model_of_another_robot_is_refused():
    with pytest.raises(ValueError, match="is a kr16 policy, not ur5"):
        rayreach.plan("exp1", planner="drl", model="kr16")


def test_obstacles_built_in_code_are_the_files_obstacles():
    plate = ObstacleSpec("box", position=(0.0, 0.4, 0.3), half_extents=(0.002, 0.1, 0.05), name="plate")
    assert get_scenario("exp1").obstacles == (plate,)
    assert as_scenario(get_scenario("exp1").to_dict()) == get_scenario("exp1")
