"""Broad random worlds: feasible, seeded, every kind drawn, goals where each kind puts them."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from geometry import signed_distance

from rayreach.robots import get_robot
from rayreach.scenarios import get_scenario
from rayreach.scenarios.broad_world import (
    BROAD_KINDS,
    EXTRA_KINDS,
    FLOOR_Z,
    GOAL_KINDS,
    BroadWorldConfig,
    BroadWorlds,
    broad_kinds,
    broad_workspace,
)
from rayreach.scenarios.feasibility import goal_configuration
from rayreach.scenarios.schema import ObstacleSpec
from rayreach.sim.kinematics import Kinematics
from rayreach.sim.scene import Scene
from rayreach.sim.transforms import rpy_to_matrix

ROBOTS = ("ur5", "kr16")
SEEDS = range(20)


class Drawn:
    """One robot's sampler (on its own scene), a second scene to check in, and the worlds of
    ``SEEDS`` with what the sampler's scene held right after each draw."""

    def __init__(self, name: str) -> None:
        self.spec = get_robot(name)
        self.kin = Kinematics(self.spec)
        self.scene = Scene(self.spec)
        self.checker = Scene(self.spec)
        self.worlds = BroadWorlds(self.kin, self.scene)
        self.drawn = []
        for seed in SEEDS:
            scenario, q = self.worlds.sample(np.random.default_rng(seed))
            held = (list(self.scene.obstacles), self.scene.in_collision())
            self.drawn.append((scenario, q, held))

    def close(self) -> None:
        self.scene.close()
        self.checker.close()


@pytest.fixture(scope="module")
def drawn():
    made = {name: Drawn(name) for name in ROBOTS}
    yield made
    for d in made.values():
        d.close()


def _local(obstacle: ObstacleSpec, point) -> np.ndarray:
    """``point`` in the frame of ``obstacle`` (centre and orientation)."""
    return rpy_to_matrix(obstacle.rpy).T @ (np.asarray(point, dtype=float) - np.asarray(obstacle.position))


def _parts(scenario, kind: str, index: int = 0) -> dict[str, ObstacleSpec]:
    prefix = f"{kind}_{index}_"
    return {o.name[len(prefix):]: o for o in scenario.obstacles if o.name.startswith(prefix)}


# ---------------------------------------------------------------------- feasibility
@pytest.mark.parametrize("robot", ROBOTS)
def test_broad_worlds_are_feasible(drawn, robot):
    """Checked in a second scene: the start is free at t = 0, its tool has the default
    orientation, and the goal configuration IK finds from the start is free."""
    d = drawn[robot]
    kin, checker = d.kin, d.checker
    low, high = broad_workspace(d.spec)
    tool_rot = rpy_to_matrix(d.spec.tool_rpy)
    for seed, (scenario, q, (held, held_collides)) in zip(SEEDS, d.drawn):
        assert scenario.name == "broad" and scenario.robot == robot
        np.testing.assert_allclose(scenario.start.joints, q)
        assert held == list(scenario.obstacles) and not held_collides  # the scene is left at the start
        assert all(o.shape in ("box", "sphere") and not o.moving for o in scenario.obstacles)
        np.testing.assert_allclose(scenario.workspace_low, low)
        np.testing.assert_allclose(scenario.workspace_high, high)

        checker.set_obstacles(scenario.obstacles)
        checker.set_joints(q)
        assert not checker.in_collision(), f"seed {seed}: the start collides"
        pose = kin.fk(q)
        start, goal = pose[:3, 3], np.asarray(scenario.goals[0])
        np.testing.assert_allclose(pose[:3, :3], tool_rot, atol=1e-3)
        np.testing.assert_allclose(checker.tcp_pose()[0], start, atol=1e-3)  # PyBullet agrees on the tip
        assert scenario.in_workspace(start) and scenario.in_workspace(goal), seed
        assert np.linalg.norm(goal - start) >= BroadWorldConfig().min_goal_distance
        q_goal = goal_configuration(kin, goal, q, np.random.default_rng(0))
        assert q_goal is not None, f"seed {seed}: the goal is unreachable"
        checker.set_joints(q_goal)
        assert not checker.in_collision(), f"seed {seed}: the goal configuration collides"
        for obs in scenario.obstacles:
            assert signed_distance(obs, goal)[0] > 0, f"seed {seed}: goal inside {obs.name}"

        kinds = broad_kinds(scenario)
        assert len(kinds) == BroadWorldConfig().n_obstacles
        assert kinds[0] in GOAL_KINDS and all(k in EXTRA_KINDS for k in kinds[1:]), kinds


@pytest.mark.parametrize("robot", ROBOTS)
def test_the_check_sees_an_obstacle_on_the_tool(drawn, robot):
    """The feasibility test above can fail: the same check reports a sphere at the tool tip."""
    d = drawn[robot]
    scenario, q, _ = d.drawn[0]
    tip = d.kin.fk(q)[:3, 3]
    d.checker.set_obstacles([*scenario.obstacles, ObstacleSpec("sphere", tuple(tip), radius=0.03)])
    d.checker.set_joints(q)
    assert d.checker.in_collision()


# ---------------------------------------------------------------------- seeding and kinds
@pytest.mark.parametrize("robot", ROBOTS)
def test_the_same_seed_gives_the_same_world(drawn, robot):
    """Whatever the scene held before, and on another scene: the world is the seed's."""
    d = drawn[robot]
    again = BroadWorlds(d.kin, d.checker)
    scenario, q = again.sample(np.random.default_rng(5))
    assert scenario == d.drawn[5][0]
    np.testing.assert_array_equal(q, d.drawn[5][1])
    other, _ = again.sample(np.random.default_rng(6))
    assert other != scenario and other.goals != scenario.goals


@pytest.mark.parametrize("robot", ROBOTS)
def test_every_kind_appears_over_the_seeds(drawn, robot):
    seen = {k for scenario, _, _ in drawn[robot].drawn for k in broad_kinds(scenario)}
    assert seen == set(BROAD_KINDS)


def test_broad_kinds_counts_each_element_once():
    scenario = get_scenario("exp1")
    named = [ObstacleSpec("box", (0, 0, 0), half_extents=(0.1, 0.1, 0.1), name=n)
             for n in ("shelf_0_board_0", "shelf_0_wall_1", "clutter_1_box_0", "clutter_1_sphere_1",
                       "wall_2_plate", "clutter_3_box_0", "goal_box_4_bottom")]
    assert broad_kinds(replace(scenario, obstacles=tuple(named))) == ["shelf", "clutter", "wall", "clutter",
                                                                         "goal_box"]
    with pytest.raises(ValueError, match="table, shelf, goal_box, clutter, wall"):
        broad_kinds(scenario)  # exp1's "plate"


# ---------------------------------------------------------------------- where the goal is
def _worlds_of(drawn, robot, kind):
    return [(s, q) for s, q, _ in drawn[robot].drawn if broad_kinds(s)[0] == kind]


@pytest.mark.parametrize("robot", ROBOTS)
def test_a_shelf_goal_is_inside_a_compartment(drawn, robot):
    """Between two boards, between two walls, within the boards' depth; the start in front of
    the open face (towards the base), at least 0.1 m off it."""
    worlds = _worlds_of(drawn, robot, "shelf")
    assert worlds
    base = np.asarray(drawn[robot].spec.base_position)
    for scenario, q in worlds:
        parts = _parts(scenario, "shelf")
        boards = sorted((o for n, o in parts.items() if n.startswith("board_")), key=lambda o: o.position[2])
        walls = [o for n, o in parts.items() if n.startswith("wall_")]
        assert len(boards) in (2, 3, 4) and len(walls) in (2, 3, 4)
        ref = boards[0]
        goal = np.asarray(scenario.goals[0])
        g = _local(ref, goal)
        below = [b for b in boards if _local(ref, b.position)[2] + b.half_extents[2] < g[2]]
        above = [b for b in boards if _local(ref, b.position)[2] - b.half_extents[2] > g[2]]
        assert below and above, f"goal {goal} not between two boards"
        xs = [(_local(ref, w.position)[0], w.half_extents[0]) for w in walls]
        assert any(x + h < g[0] for x, h in xs) and any(x - h > g[0] for x, h in xs), "not between two walls"
        assert abs(g[1]) < ref.half_extents[1], "not within the shelf's depth"
        assert all(signed_distance(o, goal)[0] > 0 for o in scenario.obstacles)
        # the open face (local -y) looks towards the base
        assert _local(ref, base)[1] < -ref.half_extents[1]
        start = drawn[robot].kin.fk(q)[:3, 3]
        assert _local(ref, start)[1] <= -ref.half_extents[1] - 0.1 + 1e-3


@pytest.mark.parametrize("robot", ROBOTS)
def test_a_goal_box_goal_is_inside_below_the_rim(drawn, robot):
    worlds = _worlds_of(drawn, robot, "goal_box")
    assert worlds
    for scenario, _q in worlds:
        parts = _parts(scenario, "goal_box")
        bottom = parts["bottom"]
        walls = [o for n, o in parts.items() if n.startswith("wall_")]
        assert len(walls) in (3, 4)
        thickness = 2 * min(min(w.half_extents) for w in walls)
        goal = np.asarray(scenario.goals[0])
        g = _local(bottom, goal)
        rim = max(w.position[2] + w.half_extents[2] for w in walls)
        assert bottom.position[2] + bottom.half_extents[2] < goal[2] < rim
        inner = np.asarray(bottom.half_extents[:2]) - thickness
        assert np.all(np.abs(g[:2]) < inner), f"goal {goal} not between the walls"


@pytest.mark.parametrize("robot", ROBOTS)
def test_a_table_goal_is_above_the_top(drawn, robot):
    worlds = _worlds_of(drawn, robot, "table")
    assert worlds
    for scenario, _q in worlds:
        top = _parts(scenario, "table")["top"]
        goal = np.asarray(scenario.goals[0])
        g = _local(top, goal)
        assert abs(g[0]) < top.half_extents[0] and abs(g[1]) < top.half_extents[1]
        assert 0.02 - 1e-9 <= g[2] - top.half_extents[2] <= 0.25 + 1e-9
        assert top.position[2] - top.half_extents[2] >= FLOOR_Z


# ---------------------------------------------------------------------- workspace
@pytest.mark.parametrize("robot", ROBOTS)
def test_the_broad_workspace_holds_the_reach_and_the_training_box(robot):
    spec = get_robot(robot)
    low, high = broad_workspace(spec)
    assert np.all(low <= spec.workspace_low) and np.all(high >= spec.workspace_high)
    assert np.prod(high - low) > 2 * np.prod(np.subtract(spec.workspace_high, spec.workspace_low))
    assert low[2] >= FLOOR_Z
    kin = Kinematics(spec)
    rng = np.random.default_rng(1)
    tips = np.array([kin.fk(q)[:3, 3] for q in rng.uniform(np.maximum(kin.lower, -np.pi),
                                                           np.minimum(kin.upper, np.pi), (300, 6))])
    above = tips[tips[:, 2] >= FLOOR_Z]
    assert np.all(above >= low) and np.all(above <= high)
    # not much larger than the reach: a stretched arm touches the box's far side
    assert np.max(above[:, 2]) > high[2] - 0.5


# ---------------------------------------------------------------------- config
@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"kinds": ("shelf", "plate")}, "table, shelf, goal_box, clutter, wall"),
        ({"kinds": ("clutter", "wall")}, "table, shelf, goal_box"),
        ({"kinds": ("table",)}, "clutter, wall"),
        ({"n_obstacles": -1}, "n_obstacles"),
        ({"min_goal_distance": -0.1}, "min_goal_distance"),
        ({"margin": -0.01}, "margin"),
        ({"start_clearance": -0.01}, "start_clearance"),
        ({"max_tries": 0}, "max_tries"),
        ({"element_sets": 0}, "element_sets"),
    ],
)
def test_bad_config_values_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        BroadWorldConfig(**kwargs)


def test_the_number_of_elements_follows_n_obstacles(drawn):
    d = drawn["ur5"]
    worlds = BroadWorlds(d.kin, d.checker, BroadWorldConfig(n_obstacles=1, kinds=("shelf",)))
    scenario, _ = worlds.sample(np.random.default_rng(0))
    assert broad_kinds(scenario) == ["shelf"]
    scenario, _ = worlds.sample(np.random.default_rng(0), 0)
    assert scenario.obstacles == ()
    with pytest.raises(ValueError, match="clutter, wall"):
        worlds.sample(np.random.default_rng(0), 2)
    with pytest.raises(ValueError, match="n_obstacles"):
        worlds.sample(np.random.default_rng(0), -1)


def test_elements_that_do_not_fit_are_drawn_anew_and_a_world_that_never_fits_names_them(drawn, monkeypatch):
    """A set of elements that fits in none of its tries gives way to another set (a run must
    not stop on one unlucky draw); only when every set fails does ``sample`` raise."""
    d = drawn["ur5"]
    worlds = BroadWorlds(d.kin, d.checker, BroadWorldConfig(n_obstacles=1, kinds=("shelf", "table"), max_tries=20))
    real = worlds._goal_scene
    tried = []
    monkeypatch.setattr(worlds, "_goal_scene", lambda kind, rng: tried.append(kind) or (
        None if kind == "shelf" else real(kind, rng)))
    kinds = [broad_kinds(worlds.sample(np.random.default_rng(seed))[0]) for seed in range(6)]
    assert kinds == [["table"]] * 6 and "shelf" in tried
    monkeypatch.setattr(worlds, "_goal_scene", lambda kind, rng: None)
    with pytest.raises(RuntimeError, match=r"20 tries for each of 5 sets of elements: \[\['(shelf|table)'\]"):
        worlds.sample(np.random.default_rng(0))


def test_the_start_keeps_its_clearance_when_asked(drawn):
    d = drawn["ur5"]
    worlds = BroadWorlds(d.kin, d.scene, BroadWorldConfig(start_clearance=0.05))
    for seed in range(5):
        scenario, q = worlds.sample(np.random.default_rng(100 + seed))
        d.checker.set_obstacles(scenario.obstacles)
        d.checker.set_joints(q)
        assert d.checker.clearance(0.05) >= 0.05 - 1e-6
