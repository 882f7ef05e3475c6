"""The goal field: the way to the goal round static obstacles, against paths worked by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rayreach.env.goal_field import FieldBatch, FieldConfig, GoalField
from rayreach.env.rewards import RewardWeights, progress_reward
from rayreach.scenarios.schema import ObstacleSpec

LOW, HIGH = np.array([-0.5, 0.0, 0.0]), np.array([0.5, 1.0, 0.6])
GOAL = np.array([0.0, 0.5, 0.2])


def _wall(yaw: float = 0.0, gap: float = 0.06, height: float = 0.05) -> ObstacleSpec:
    """An upright plate 4 mm thick, 0.2 m wide, ``2 height`` tall, ``gap`` on the -y side of the goal."""
    return ObstacleSpec("box", (0.0, 0.5 - gap, 0.21), rpy=(0.0, 0.0, yaw), half_extents=(0.1, 0.002, height))


def test_without_obstacles_the_way_is_the_straight_line_within_the_grid_error():
    field = GoalField.build([], GOAL, LOW, HIGH)
    rng = np.random.default_rng(0)
    for point in rng.uniform(LOW + 0.05, HIGH - 0.05, (200, 3)):
        straight = float(np.linalg.norm(point - GOAL))
        # 26 neighbours: at most about 8 % longer than the straight line, never shorter
        assert straight - 1e-9 <= field.distance(point) <= 1.09 * straight + 0.02


def test_behind_a_wall_the_way_goes_over_it():
    wall = _wall()
    field = GoalField.build([wall], GOAL, LOW, HIGH)
    cell = field.cell
    grown = 0.75 * cell
    point = np.array([0.0, 0.3, 0.2])  # in front of the wall, at the goal's height
    top = 0.21 + 0.05 + grown  # the grown wall's top edge
    over = math.hypot(0.5 - 0.06 - 0.3, top - 0.2) + math.hypot(0.06, top - 0.2)  # up to the edge, then down
    way = field.distance(point)
    assert way > float(np.linalg.norm(point - GOAL)) + 0.05
    assert over - 1e-9 <= way <= 1.09 * over + 2 * cell
    beside = np.array([0.0, 0.6, 0.2])  # the goal's side: nothing in between
    assert field.distance(beside) == pytest.approx(0.1, abs=0.01)


@pytest.mark.parametrize("yaw", [0.0, 0.3, math.pi / 4, 1.1])
def test_a_thin_turned_plate_lets_no_path_through(yaw):
    """A tall plate, turned about z: the way round it is longer than through it by far."""
    plate = ObstacleSpec("box", (0.0, 0.44, 0.2), rpy=(0.0, 0.0, yaw), half_extents=(0.4, 0.002, 0.3))
    field = GoalField.build([plate], GOAL, LOW, HIGH)
    front = np.array([0.0, 0.5, 0.2]) + 0.15 * np.array([math.sin(yaw), -math.cos(yaw), 0.0])
    assert field.distance(front) > 0.3


def test_moving_obstacles_are_left_out_and_a_point_next_to_an_obstacle_has_no_value():
    moving = ObstacleSpec("box", (0.0, 0.44, 0.2), half_extents=(0.4, 0.002, 0.3), velocity=(0.1, 0.0, 0.0))
    field = GoalField.build([moving], GOAL, LOW, HIGH)
    assert field.distance(np.array([0.0, 0.35, 0.2])) == pytest.approx(0.15, abs=0.015)
    static = ObstacleSpec("box", (0.0, 0.3, 0.2), half_extents=(0.05, 0.05, 0.05))
    inside = GoalField.build([static], GOAL, LOW, HIGH)
    assert math.isinf(inside.distance(np.array([0.0, 0.3, 0.2])))
    w = RewardWeights(progress=10.0)
    assert progress_reward(math.inf, 0.3, w) == 0.0 and progress_reward(0.3, math.inf, w) == 0.0
    assert progress_reward(0.3, 0.2, w) == pytest.approx(1.0)


def test_a_batch_looks_up_each_world_in_its_own_field():
    fields = [GoalField.build([_wall()], GOAL, LOW, HIGH), GoalField.build([], GOAL + 0.1, LOW, HIGH,
                                                                           FieldConfig(cell=0.03))]
    batch = FieldBatch(3)
    batch.set_world(2, fields[0])
    batch.set_world(0, fields[1])
    points = np.array([[0.0, 0.3, 0.2], [0.1, 0.4, 0.25]])
    got = batch.distances(points, np.array([2, 0]))
    assert got == pytest.approx([fields[0].distance(points[0]), fields[1].distance(points[1])])


def test_a_large_workspace_gets_larger_cells_and_bad_settings_are_refused():
    config = FieldConfig(max_cells=10_000)
    assert config.cell_for(np.array([1.6, 1.2, 1.4])) > 0.05
    assert config.cell_for(np.array([0.1, 0.1, 0.1])) == config.cell
    with pytest.raises(ValueError, match="clearance_cells"):
        FieldConfig(clearance_cells=0.2)
    with pytest.raises(ValueError, match="cell"):
        FieldConfig(cell=0.0)
