"""The seven experiments, users' scene files and random worlds."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest
from geometry import segment_hits, signed_distance

from rayreach.env.reach import ReachEnv
from rayreach.sim.kinematics import IKParams
from rayreach.scenarios import EXPERIMENTS, ScenarioError, get_scenario
from rayreach.scenarios.feasibility import goal_configuration, solve_start
from rayreach.scenarios.random_world import KINDS, RandomWorldConfig, RandomWorlds, shelf_boxes, world_kinds

ROBOT_OF = {
    "exp1": "ur5",
    "exp2": "ur5",
    "exp3": "ur5",
    "exp4": "kr16",
    "exp5": "kr16",
    "exp6": "kr16",
    "exp7": "kr16",
}


@pytest.fixture
def world(rigs):
    """Per experiment: (scenario, rig with the scenario's obstacles, start configuration)."""
    made = []

    def load(name):
        scenario = get_scenario(name)
        assert scenario.base_position is None and scenario.base_rpy is None  # the rigs use the default base
        rig = rigs[scenario.robot]
        rig.scene.set_obstacles(scenario.obstacles)
        made.append(rig)
        return scenario, rig, solve_start(scenario, rig.kin)

    yield load
    for rig in made:
        rig.scene.set_obstacles([])


# ---------------------------------------------------------------------- built-ins
def test_all_seven_experiments_load():
    assert EXPERIMENTS == tuple(f"exp{i}" for i in range(1, 8))
    for name in EXPERIMENTS:
        scenario = get_scenario(name)
        assert scenario.name == name
        assert scenario.robot == ROBOT_OF[name]
        assert scenario.obstacles, name
        for goal in scenario.goals:
            assert scenario.in_workspace(goal)
    assert len(get_scenario("exp2").goals) == 2
    assert all(len(get_scenario(n).goals) == 1 for n in EXPERIMENTS if n != "exp2")


def test_exp3_has_a_plate_moving_at_0_2_m_per_s():
    scenario = get_scenario("exp3")
    moving = [o for o in scenario.obstacles if o.moving]
    assert len(moving) == 1 and scenario.has_moving_obstacles
    assert math.sqrt(sum(v * v for v in moving[0].velocity)) == pytest.approx(0.2)
    assert moving[0].velocity == (0.0, 0.2, 0.0)


def test_only_exp3_moves():
    for name in EXPERIMENTS:
        assert get_scenario(name).has_moving_obstacles == (name == "exp3")


def test_unknown_scenario_name_lists_the_experiments():
    with pytest.raises(ScenarioError) as err:
        get_scenario("exp8")
    for name in EXPERIMENTS:
        assert name in str(err.value)


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_start_is_collision_free_and_goals_reachable(world, name):
    scenario, rig, q_start = world(name)
    kin, scene = rig.kin, rig.scene
    assert np.all(q_start >= kin.lower) and np.all(q_start <= kin.upper)
    start = kin.fk(q_start)
    if scenario.start.position is not None:  # a pose start is met exactly
        np.testing.assert_allclose(start[:3, 3], scenario.start.position, atol=1e-4)
    assert scenario.in_workspace(start[:3, 3])
    scene.set_joints(q_start)
    assert not scene.in_collision()
    # independent check: the tool tip is outside every obstacle
    assert all(signed_distance(o, start[:3, 3])[0] > 0 for o in scenario.obstacles)
    rng = np.random.default_rng(0)
    for goal in scenario.goals:
        q_goal = goal_configuration(kin, goal, q_start, rng)
        assert q_goal is not None, f"{name}: goal {goal} unreachable"
        assert np.linalg.norm(kin.fk(q_goal)[:3, 3] - goal) < 1e-4
        assert np.all(q_goal >= kin.lower) and np.all(q_goal <= kin.upper)
        assert all(signed_distance(o, goal)[0] > 0 for o in scenario.obstacles)  # goal in free space


@pytest.mark.parametrize("name, legs", [("exp1", [(-1, 0)]), ("exp2", [(-1, 0), (0, 1)])])
def test_straight_cartesian_path_is_blocked_ur5(world, name, legs):
    """exp1 and exp2: the straight line start -> goal (and goal 0 -> goal 1) crosses a plate."""
    scenario, rig, q_start = world(name)
    tip = rig.kin.fk(q_start)[:3, 3]
    points = {-1: tip, **{i: np.asarray(g) for i, g in enumerate(scenario.goals)}}
    caster = rig.scene.caster("numpy")
    for a, b in legs:
        hits = segment_hits(scenario.obstacles, points[a], points[b])
        assert hits, f"{name}: straight path {a} -> {b} is free"
        d = points[b] - points[a]
        length = float(np.linalg.norm(d))
        assert caster.cast(points[a][None], (d / length)[None], length)[0] < 1.0
    if name == "exp2":
        names = [scenario.obstacles[i].name for i in segment_hits(scenario.obstacles, tip, scenario.goals[0])]
        assert names == ["plate_right"]
        names = [scenario.obstacles[i].name for i in segment_hits(scenario.obstacles, *scenario.goals)]
        assert names == ["plate_left"]


@pytest.mark.parametrize("name", ["exp4", "exp5", "exp6", "exp7"])
def test_straight_path_into_the_shelf_collides_kr16(world, name):
    """exp4-7: the tip's straight line passes through the compartment's opening, but the arm
    following it (5 mm steps, IK keeping the start orientation) hits a shelf board."""
    scenario, rig, q_start = world(name)
    kin, scene = rig.kin, rig.scene
    start = kin.fk(q_start)
    a, b = start[:3, 3], np.asarray(scenario.goals[0])
    n = int(np.ceil(np.linalg.norm(b - a) / 0.005))
    q = q_start
    collided_at = None
    for k in range(1, n + 1):
        point = a + (b - a) * k / n
        result = kin.ik(point, start[:3, :3], q, IKParams(tolerance=1e-4, max_iterations=100))
        assert result.converged, f"{name}: IK failed at step {k}/{n} before any collision"
        q = result.q
        scene.set_joints(q)
        if scene.in_collision():
            collided_at = k
            break
    assert collided_at is not None, f"{name}: the arm follows the straight line to the goal without collision"
    boards = {scenario.obstacles[i].name for i in scene.colliding_obstacles()}
    assert boards and all(b_.startswith("board_") for b_ in boards)


def test_exp3_plate_covers_the_goal_then_clears_it():
    scenario = get_scenario("exp3")
    plate = next(o for o in scenario.obstacles if o.moving)
    goal = np.asarray(scenario.goals[0])
    hx, hy, hz = plate.half_extents

    def covers(t):
        c = np.asarray(plate.position_at(t))
        return abs(goal[0] - c[0]) <= hx + 1e-12 and abs(goal[1] - c[1]) <= hy + 1e-12 and c[2] - hz > goal[2]

    assert plate.rpy == (0.0, 0.0, 0.0)
    assert covers(0.0)
    assert covers(0.25)  # squarely above it a moment later
    assert not covers(1.0)
    np.testing.assert_allclose(plate.position_at(1.0), np.asarray(plate.position) + [0.0, 0.2, 0.0])


def test_shelf_boxes_reproduce_exp4():
    boxes, compartments = shelf_boxes((0.0, 0.25, 1.1))
    exp4 = get_scenario("exp4").obstacles
    assert len(boxes) == len(exp4) == 6
    for ours, theirs in zip(boxes, exp4):
        assert ours.shape == theirs.shape == "box"
        assert ours.name == theirs.name
        np.testing.assert_allclose(ours.position, theirs.position, atol=1e-12)
        np.testing.assert_allclose(ours.half_extents, theirs.half_extents, atol=1e-12)
    # the goals of exp4..exp7 lie straight behind the four compartments, 0.25 m deeper
    for name, centre in zip(("exp4", "exp5", "exp6", "exp7"), compartments):
        goal = get_scenario(name).goals[0]
        np.testing.assert_allclose(goal, np.asarray(centre) + [0.0, 0.25, 0.0], atol=1e-12)


def test_scenario_round_trips_through_json(tmp_path):
    for name in EXPERIMENTS:
        scenario = get_scenario(name)
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps(scenario.to_dict()))
        assert get_scenario(path) == scenario


# ---------------------------------------------------------------------- user scene files
BASE = {
    "name": "mine",
    "robot": "ur5",
    "start": {"position": [0.15, 0.4, 0.3], "rpy": [math.pi, 0.0, math.pi]},
    "goals": [[-0.15, 0.4, 0.3]],
    "workspace": {"low": [-0.4, 0.3, 0.2], "high": [0.4, 0.7, 0.5]},
    "obstacles": [
        {"name": "plate", "shape": "box", "position": [0.0, 0.4, 0.3], "half_extents": [0.002, 0.1, 0.05]}
    ],
}


def write(tmp_path, data, name="scene.json"):
    path = tmp_path / name
    path.write_text(json.dumps(data))
    return path


def modified(**changes):
    data = copy.deepcopy(BASE)
    for key, value in changes.items():
        if value is None:
            del data[key]
        else:
            data[key] = value
    return data


def test_user_scene_file_loads(tmp_path):
    scenario = get_scenario(write(tmp_path, BASE))
    assert scenario.name == "mine" and scenario.robot == "ur5"
    assert scenario.goals == ((-0.15, 0.4, 0.3),)
    assert scenario.obstacles[0].half_extents == (0.002, 0.1, 0.05)
    assert get_scenario(str(write(tmp_path, BASE, "other.json"))).goals == scenario.goals


@pytest.mark.parametrize(
    "data, needles",
    [
        (modified(robot="ur3"), ["robot", "ur3", "kr16, ur10, ur5"]),
        (modified(goals=[[-0.15, 0.4, 0.3], [0.0, 0.9, 0.3]]), ["goals[1]", "outside the workspace"]),
        (
            modified(obstacles=[{"shape": "box", "position": [0, 0.4, 0.3]}]),
            ["obstacles[0].half_extents", "missing"],
        ),
        (
            modified(obstacles=[{"shape": "cone", "position": [0, 0.4, 0.3]}]),
            ["obstacles[0].shape", "cone", "box, sphere, cylinder, mesh"],
        ),
        (modified(goals=[[0.1, 0.4]]), ["goals[0]", "3 numbers"]),
        (
            modified(obstacles=[{"shape": "sphere", "position": [0, 0.4], "radius": 0.05}]),
            ["obstacles[0].position", "3 numbers"],
        ),
        (
            modified(obstacles=[{"shape": "sphere", "position": [0, 0.4, 0.3], "radius": -0.05}]),
            ["obstacles[0].radius", "positive"],
        ),
        (
            modified(obstacles=[{"shape": "cylinder", "position": [0, 0.4, 0.3], "radius": 0.05}]),
            ["obstacles[0].height", "missing"],
        ),
        (
            modified(
                obstacles=[{"shape": "sphere", "position": [0, 0.4, 0.3], "radius": 0.05, "colour": "red"}]
            ),
            ["obstacles[0]", "colour"],
        ),
        (
            modified(obstacles=[{"shape": "mesh", "position": [0, 0.4, 0.3], "file": "nope.obj"}]),
            ["obstacles[0].file", "nope.obj"],
        ),
        (modified(gravity=[0, 0, -9.8]), ["unknown field", "gravity"]),
        (modified(start={"joints": [0, 0, 0]}), ["start.joints", "6 numbers"]),
        (modified(start={"position": [0.15, 0.4, 0.9]}), ["start.position", "outside the workspace"]),
        (modified(start={}), ["start"]),
        (modified(goals=[]), ["goals"]),
        (modified(goals=None), ["goals", "missing"]),
        (modified(workspace={"low": [0.4, 0.3, 0.2], "high": [-0.4, 0.7, 0.5]}), ["workspace", "low.x"]),
        (modified(goals=[[float("nan"), 0.4, 0.3]]), ["goals[0][0]", "finite"]),
        (modified(goals=[[True, 0.4, 0.3]]), ["goals[0][0]"]),
    ],
)
def test_bad_scene_files_name_the_field(tmp_path, data, needles):
    path = write(tmp_path, data)
    with pytest.raises(ScenarioError) as err:
        get_scenario(path)
    message = str(err.value)
    assert "scene.json" in message
    for needle in needles:
        assert needle in message, f"{needle!r} not in {message!r}"


def test_invalid_json_and_missing_file(tmp_path):
    bad = tmp_path / "broken.json"
    bad.write_text("{not json")
    with pytest.raises(ScenarioError, match="not valid JSON"):
        get_scenario(bad)
    with pytest.raises(ScenarioError, match="does not exist"):
        get_scenario(tmp_path / "absent.json")


def test_obstacle_overlapping_the_start_is_named(tmp_path):
    data = modified(
        obstacles=[
            {
                "name": "plate",
                "shape": "box",
                "position": [0.0, 0.4, 0.3],
                "half_extents": [0.002, 0.1, 0.05],
            },
            {"name": "blocker", "shape": "sphere", "position": [0.15, 0.4, 0.35], "radius": 0.04},
        ]
    )
    with pytest.raises(ScenarioError) as err:
        ReachEnv(scenario=write(tmp_path, data))
    assert "blocker" in str(err.value)
    assert "plate" not in str(err.value).replace("blocker", "")


def test_unreachable_goal_inside_the_workspace(tmp_path):
    data = modified(workspace={"low": [-5, -5, -5], "high": [5, 5, 5]}, goals=[[3.0, 0.4, 0.5]])
    with pytest.raises(ScenarioError) as err:
        ReachEnv(scenario=write(tmp_path, data))
    assert "unreachable" in str(err.value) and "goals[0]" in str(err.value)


def test_scenario_for_another_robot_is_refused(tmp_path):
    with pytest.raises(ScenarioError, match="kr16"):
        ReachEnv(robot="kr16", scenario=write(tmp_path, BASE))


def test_start_joints_outside_limits(tmp_path):
    data = modified(start={"joints": [0.0, -1.0, 4.0, 0.0, 0.0, 0.0]})
    with pytest.raises(ScenarioError, match="elbow_joint"):
        ReachEnv(scenario=write(tmp_path, data))


# ---------------------------------------------------------------------- random worlds
@pytest.fixture(scope="module")
def ur5_random_env():
    env = ReachEnv(robot="ur5")
    yield env
    env.close()


def _check_random_world(env):
    scenario = env.scenario
    kin, scene = env.kin, env.scene
    q = env.q
    goal = np.asarray(scenario.goals[0])
    start = kin.fk(q)[:3, 3]
    scene.set_joints(q)
    assert not scene.in_collision()
    assert scenario.in_workspace(start) and scenario.in_workspace(goal)
    assert np.linalg.norm(goal - start) >= RandomWorldConfig().min_goal_distance
    q_goal = goal_configuration(kin, goal, q, np.random.default_rng(0))
    assert q_goal is not None
    for obs in scenario.obstacles:
        if obs.shape in ("box", "sphere", "cylinder"):
            assert signed_distance(obs, goal)[0] > 0, f"goal inside {obs.name}"
            assert signed_distance(obs, start)[0] > 0, f"start inside {obs.name}"


def test_random_worlds_ur5_are_feasible(ur5_random_env):
    env = ur5_random_env
    env.set_n_obstacles(3)
    for seed in range(20):
        env.reset(seed=seed)
        _check_random_world(env)
        assert len(world_kinds(env.scenario)) == 3


def test_random_world_obstacle_count_follows_n_obstacles_ur5(ur5_random_env):
    env = ur5_random_env
    try:
        for n in (0, 1, 5):
            env.set_n_obstacles(n)
            for seed in range(5):
                env.reset(seed=100 + seed)
                assert len(world_kinds(env.scenario)) == n
                assert len(env.scene.obstacles) == len(env.scenario.obstacles)
                _check_random_world(env)
    finally:
        env.set_n_obstacles(3)
    with pytest.raises(ValueError):
        env.set_n_obstacles(-1)


def test_random_worlds_kr16_count_a_shelf_as_one_obstacle():
    """``RandomWorldConfig.n_obstacles``: "How many obstacles (a shelf counts as one)"; a
    shelf expands into 6 boxes. The KR16 draws the shelf in 3 of 7 draws, so among these
    seeds some drew it twice among three obstacles (the second draw is replaced)."""
    env = ReachEnv(robot="kr16")
    try:
        for seed in range(12):
            env.reset(seed=seed)
            _check_random_world(env)
            names = [o.name for o in env.scenario.obstacles]
            assert len([n for n in names if n.startswith("shelf_")]) in (0, 6)
            units = len(world_kinds(env.scenario))
            assert units == 3, f"seed {seed}: {units} obstacles (shelf counted once), asked for 3: {names}"
            board = next((o for o in env.scenario.obstacles if o.name == "shelf_board_0"), None)
            if board is not None:  # the tool starts before the open face, as in exp4..exp7
                front = board.position[1] - board.half_extents[1]
                tip = env.scene.tcp_pose()[0]
                assert tip[1] <= front - 0.1 + 1e-3, f"seed {seed}: start {tip} not in front of {front}"
                assert abs(tip[0] - board.position[0]) <= board.half_extents[0] + 1e-3
    finally:
        env.close()


def _worlds_of_one_kind(env, kind):
    return RandomWorlds(env.kin, env.scene, RandomWorldConfig(kinds=(kind,)))


@pytest.mark.parametrize("robot", ["ur5", "kr16"])
def test_world_kinds_names_each_drawn_kind_once(robot, ur5_random_env):
    """A world drawn from one kind names it once per draw (a slot's two plates and a shelf's
    six boxes are one draw; a second shelf draw is replaced, here by nothing)."""
    env = ur5_random_env if robot == "ur5" else ReachEnv(robot="kr16")
    rng = np.random.default_rng(5)
    try:
        for kind in dict.fromkeys(env.spec_robot.training_kinds):
            scenario, _q = _worlds_of_one_kind(env, kind).sample(rng, 2)
            assert world_kinds(scenario) == (["shelf"] if kind == "shelf" else [kind, kind]), kind
    finally:
        if robot == "kr16":
            env.close()
    assert set(KINDS) >= set(env.spec_robot.training_kinds)


def test_world_kinds_refuses_an_obstacle_no_random_world_draws():
    with pytest.raises(ValueError, match="goal_slot"):
        world_kinds(get_scenario("exp1"))


def test_goal_slot_puts_the_goal_between_two_parallel_plates(ur5_random_env):
    """goal_slot (exp2's pattern): two upright plates, parallel, on opposite sides of the goal,
    each 0.08 to 0.12 m from it along their common normal."""
    worlds = _worlds_of_one_kind(ur5_random_env, "goal_slot")
    rng = np.random.default_rng(3)
    for _ in range(5):
        scenario, _q = worlds.sample(rng, 1)
        goal = np.asarray(scenario.goals[0])
        first, second = scenario.obstacles
        assert first.half_extents[0] == second.half_extents[0] == 0.002
        normal = np.array([np.cos(first.rpy[2]), np.sin(first.rpy[2]), 0.0])
        assert abs(np.cos(second.rpy[2] - first.rpy[2]) + 1.0) < 1e-9  # facing each other
        offsets = [float(np.dot(np.asarray(o.position) - goal, normal)) for o in (first, second)]
        assert 0.08 <= offsets[0] <= 0.12 and -0.12 <= offsets[1] <= -0.08
        for o in (first, second):  # no sideways shift: the goal is between the plates
            along = np.asarray(o.position) - goal - np.dot(np.asarray(o.position) - goal, normal) * normal
            assert np.linalg.norm(along[:2]) < 1e-9


def test_goal_cover_moves_away_over_the_goal(ur5_random_env):
    """goal_cover (exp3's pattern) is always a low plate that moves: a static one either sits
    where the wrist must be or does not matter."""
    worlds = _worlds_of_one_kind(ur5_random_env, "goal_cover")
    rng = np.random.default_rng(4)
    for _ in range(5):
        scenario, _q = worlds.sample(rng, 1)
        (cover,) = scenario.obstacles
        goal = np.asarray(scenario.goals[0])
        assert cover.moving
        assert 0.04 <= cover.position[2] - goal[2] <= 0.07
        np.testing.assert_allclose(cover.position[:2], goal[:2])


def test_a_cover_speed_slows_the_covers_alone_and_leaves_the_draws_in_step(ur5_random_env):
    """The same seed draws the same world with the cover's speed from ``cover_speed``: a
    training option must not shift which worlds a seed gives."""
    base = _worlds_of_one_kind(ur5_random_env, "goal_cover")
    slow = RandomWorlds(ur5_random_env.kin, ur5_random_env.scene,
                        RandomWorldConfig(kinds=("goal_cover",), cover_speed=(0.03, 0.031)))
    for seed in range(4):
        (usual,), (slowed,) = (w.sample(np.random.default_rng(seed), 1)[0].obstacles for w in (base, slow))
        speed = float(np.linalg.norm(slowed.velocity))
        assert 0.03 <= speed <= 0.031
        assert 0.05 <= float(np.linalg.norm(usual.velocity)) <= 0.2
        assert slowed.position == usual.position
        np.testing.assert_allclose(np.asarray(slowed.velocity) / speed,
                                   np.asarray(usual.velocity) / np.linalg.norm(usual.velocity))


def test_random_worlds_are_seeded(ur5_random_env):
    env = ur5_random_env
    env.reset(seed=5)
    first = (env.scenario, env.q.copy())
    env.reset(seed=6)
    env.reset(seed=5)
    assert env.scenario == first[0]
    np.testing.assert_array_equal(env.q, first[1])


def test_scene_clearance_is_the_gap_to_the_nearest_obstacle():
    """A sphere 3 cm below the tip of exp1's downward tool (whose flat end is the tip)."""
    from exp1_scenes import exp1_around_the_tool
    from rayreach.scenarios.schema import ObstacleSpec

    gap, radius = 0.03, 0.02
    env = exp1_around_the_tool([lambda ee: ObstacleSpec("sphere", (ee[0], ee[1], ee[2] - gap - radius),
                                                         radius=radius)])
    try:
        env.reset(seed=0)
        assert env.scene.clearance(0.1) == pytest.approx(gap, abs=2e-3)
        assert env.scene.clearance(0.01) == 0.01  # nothing that near
    finally:
        env.close()


def _nearest_obstacle(scene) -> float:
    import pybullet as p

    return min(c[8] for body in scene._obstacle_ids
               for c in p.getClosestPoints(scene.robot, body, 1.0, physicsClientId=scene.client))


def test_random_worlds_keep_the_start_clear_of_obstacles_when_asked(ur5_random_env):
    env = ur5_random_env
    for clearance, all_clear in ((0.0, False), (0.05, True)):
        worlds = RandomWorlds(env.kin, env.scene, RandomWorldConfig(start_clearance=clearance))
        nearest = []
        for seed in range(15):
            worlds.sample(np.random.default_rng(seed), 3)  # leaves the scene at the start
            nearest.append(_nearest_obstacle(env.scene))
        assert (min(nearest) >= 0.05) == all_clear, (clearance, min(nearest))
    with pytest.raises(ValueError, match="start_clearance"):
        RandomWorldConfig(start_clearance=-0.01)
