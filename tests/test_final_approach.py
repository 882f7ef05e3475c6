"""The final approach: its path test on its own, the perception's ray hit points against
PyBullet's ray casts, and the straight step in a scene acting through ``ActingEnv``
(PyBullet's contacts), for acting and training."""

from __future__ import annotations

import dataclasses

import numpy as np
import pybullet as p
import pytest

from exp1_scenes import SLIDING_STACK, acting_around_the_tool, exp1_around_the_tool, layers
from rayreach.acting import SOURCES, ActingConfig, ActingEnv
from rayreach.acting.config import ROBOT_RADII
from rayreach.acting.final_approach import FinalApproach
from rayreach.acting.shield import ACTING_SAFETY
from rayreach.env.reach import N_ROBOT_OBS, ReachEnv
from rayreach.learning.train import TrainConfig, make_env_fn, set_trainable
from rayreach.robots import get_robot
from rayreach.scenarios.schema import ObstacleSpec
from rayreach.sim.geometry import distances_to_parallelogram, distances_to_segment
from rayreach.sim.transforms import rotvec_to_matrix

APPROACH = FinalApproach(radius=0.1, margin=0.02, ee_step=0.005)
NOTHING = np.zeros((0, 3))


def test_steps_straight_only_within_the_radius():
    """Along the offset, its largest axis a full step (the action's limit), so the step stays
    on the path tested; clipping each axis would turn a goal 3 cm ahead and 2 mm aside into a
    step 2 mm aside. Within a step of the goal, the step lands on it."""
    np.testing.assert_allclose(APPROACH.action(np.array([0.03, -0.002, 0.0]), NOTHING),
                               [1.0, -0.2 / 3, 0.0, 0.0, 0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(APPROACH.action(np.array([0.003, 0.0, -0.001]), NOTHING),
                               [0.6, 0.0, -0.2, 0.0, 0.0, 0.0], atol=1e-6)
    assert APPROACH.action(np.array([0.11, 0.0, 0.0]), NOTHING) is None


@pytest.mark.parametrize("hit,clear", [
    ((0.04, 0.03, 0.0), True),     # a wall 3 cm beside the path: the tool passes it
    ((0.04, 0.01, 0.0), False),    # 1 cm beside the path
    ((0.09, 0.0, 0.015), False),   # 1.8 cm from the goal, beyond it
    ((-0.015, 0.0, 0.0), True),    # 1.5 cm behind the tool: the path leads away from it
    ((0.12, 0.0, 0.0), True),      # 4 cm past the goal
    ((0.04, -0.2, 0.0), True),     # far to the side
])
def test_anything_a_ray_sees_within_the_margin_of_the_path_leaves_it_to_the_policy(hit, clear):
    offset = np.array([0.08, 0.0, 0.0])
    action = APPROACH.action(offset, np.array([hit, (0.3, 0.3, 0.3)]))
    assert (action is not None) == clear
    if clear:
        np.testing.assert_allclose(action, [1.0, 0, 0, 0, 0, 0], atol=1e-6)


def _brute_force_distances(points, u, v, n=401):
    s, t = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    area = s.reshape(-1, 1) * u + t.reshape(-1, 1) * v
    return np.array([np.linalg.norm(area - x, axis=1).min() for x in points])


@pytest.mark.parametrize("u,v", [
    ((0.08, 0.0, 0.0), (0.0, 0.0, 0.13)),     # the tool upright, moving sideways
    ((0.05, 0.03, -0.02), (0.1, -0.05, 0.1)),  # oblique
    ((0.0, 0.0, -0.06), (0.0, 0.0, 0.13)),    # moving along the tool: a segment
    ((0.05, 0.0, 0.0), (0.0, 0.0, 0.0)),      # no tool: the tip's path
])
def test_distances_to_the_swept_area_match_a_dense_sampling(u, v):
    rng = np.random.default_rng(0)
    points = rng.uniform(-0.15, 0.2, (40, 3))
    u, v = np.array(u), np.array(v)
    np.testing.assert_allclose(distances_to_parallelogram(points, u, v), _brute_force_distances(points, u, v),
                               atol=3e-4)


def test_the_tool_behind_the_tip_must_clear_what_the_rays_see_too():
    """A plate edge 6 cm above the tip's path, 4 cm ahead, blocks a downward 13 cm tool of
    2 cm radius and not a tip without a tool; moved 4.5 cm to the side it is clear of the
    tool too, at 3.5 cm it is not."""
    offset, down = np.array([0.08, 0.0, 0.0]), np.array([0.0, 0.0, -1.0])
    hits = np.array([(0.04, 0.0, 0.06), (0.3, 0.3, 0.3)])
    assert APPROACH.action(offset, hits, down) is not None
    tool = FinalApproach(radius=0.1, margin=0.02, ee_step=0.005, tool_length=0.13, tool_radius=0.02, turn=False)
    assert tool.action(offset, hits, down) is None
    assert tool.action(offset, hits + [0.0, 0.045, 0.0], down) is not None  # 4.5 cm to the side: clear
    assert tool.action(offset, hits + [0.0, 0.035, 0.0], down) is None  # 3.5 cm: under 2 + 2 cm


TOOL = FinalApproach(radius=0.1, margin=0.02, ee_step=0.005, rot_step=0.005, tool_length=0.13, tool_radius=0.02)


def test_where_only_the_tools_back_blocks_the_path_the_tool_turns_about_its_tip_towards_it():
    """The plate edge of the test above: the tip's own path is clear, so instead of the
    refused step the tool turns, a full rotation step about -y, which tilts a downward tool
    towards +x, the path; pointing along the path, it takes the straight step."""
    offset, down = np.array([0.08, 0.0, 0.0]), np.array([0.0, 0.0, -1.0])
    hits = np.array([(0.04, 0.0, 0.06), (0.3, 0.3, 0.3)])
    np.testing.assert_allclose(TOOL.action(offset, hits, down), [0, 0, 0, 0, -1.0, 0], atol=1e-6)
    turned = rotvec_to_matrix(np.array([0.0, -0.005, 0.0])) @ down
    assert turned[0] > 0 and turned[2] < 0  # towards +x, still mostly down
    np.testing.assert_allclose(TOOL.action(offset, hits, np.array([1.0, 0.0, 0.0])), [1.0, 0, 0, 0, 0, 0], atol=1e-6)
    assert dataclasses.replace(TOOL, turn=False).action(offset, hits, down) is None


@pytest.mark.parametrize("hit", [
    (0.04, 0.0, 0.02),     # 2 cm above the tip's own path: under its 2 cm radius + 2 cm
    (-0.03, 0.0, 0.13),    # 3 cm behind the tool's back, where turning towards +x swings it
])
def test_no_turn_where_the_tip_is_blocked_or_the_turn_swings_the_tool_nearer(hit):
    hits = np.array([(0.04, 0.0, 0.06), hit])
    assert TOOL.action(np.array([0.08, 0.0, 0.0]), hits, np.array([0.0, 0.0, -1.0])) is None


def test_what_the_tool_is_already_near_blocks_only_a_path_that_comes_nearer():
    """A wall along the (downward) tool, 2.5 cm from its axis (under its 2 cm radius plus
    1 cm): a path along the wall passes, one towards it does not."""
    tool = FinalApproach(radius=0.1, margin=0.01, ee_step=0.005, tool_length=0.13, tool_radius=0.02)
    down = np.array([0.0, 0.0, -1.0])
    wall = np.array([(x, 0.025, z) for x in (-0.05, 0.0, 0.05, 0.1) for z in (0.0, 0.05, 0.1)])
    assert tool.action(np.array([0.08, 0.0, 0.0]), wall, down) is not None
    assert tool.action(np.array([0.06, 0.0, -0.04]), wall, down) is not None  # down and along
    assert tool.action(np.array([0.06, 0.004, 0.0]), wall, down) is None  # 4 mm nearer


@pytest.mark.parametrize("field,value", [("radius", 0.0), ("margin", -0.01), ("ee_step", float("nan")),
                                         ("rot_step", 0.0), ("axial_radius", 0.0), ("axial_angle", -0.1),
                                         ("tool_length", -0.1), ("tool_radius", -0.02), ("stall_steps", -1),
                                         ("stall_steps", 2.5), ("stall_gain", 0.0)])
def test_bad_settings_are_refused_by_name(field, value):
    with pytest.raises(ValueError, match=field):
        FinalApproach(**{field: value})


def _wall_beside(ee):  # an upright plate 5 cm to the +y of the path (3 cm from the 2 cm tool), 4 cm tall above and below it
    return ObstacleSpec("box", (ee[0] + 0.04, ee[1] + 0.055, ee[2]), half_extents=(0.05, 0.005, 0.04))


def _wall_across(ee):  # the same plate turned across the path, 4 cm ahead
    return ObstacleSpec("box", (ee[0] + 0.04, ee[1], ee[2]), half_extents=(0.005, 0.05, 0.04))


def test_ray_hits_lie_where_pybullet_casts_them():
    env = exp1_around_the_tool([_wall_beside], np.array([0.08, 0.0, 0.0]))
    try:
        env.reset(seed=0)
        seen = env.perceive()
        hits = seen.hits
        np.testing.assert_allclose(seen.hit_points - seen.ee_position, hits)
        np.testing.assert_array_equal(seen.ee_position, env.ee_pos)
        origins, directions = env.rays.world_rays(env.frames)
        np.testing.assert_allclose(seen.origins, origins)
        np.testing.assert_allclose(seen.directions, directions)
        results = p.rayTestBatch(origins.tolist(), (origins + env.config.ray_range * directions).tolist(),
                                 physicsClientId=env.scene.client)
        seen = [r[3] for r in results if r[0] >= 0 and r[0] != env.scene.robot]  # the rays never see the arm
        reference = np.array(seen) - env.ee_pos
        assert len(hits) == len(reference) >= 5  # the wall is in view
        np.testing.assert_allclose(hits, reference, atol=1e-4)
    finally:
        env.close()


def _idle(env, steps=40):
    """Steps with a zero action (a policy that stopped); the last info, with every step's
    ``info["acting"]["source"]`` under ``"sources"`` where the env acts through the layers."""
    env.reset(seed=0)
    sources = []
    for _ in range(steps):
        _, _, terminated, _, info = env.step(np.zeros(6, np.float32))
        sources.append(info.get("acting", {}).get("source"))
        if terminated:
            break
    return {**info, "sources": sources}


IDLE = {"policy", "held"}
"""What an idle policy's steps may report: its own zero step, which holds the arm still."""


def _approach(obstacles, goal_offset, approach: FinalApproach | None = FinalApproach(), **options) -> ActingEnv:
    """exp1 round the tool acting through ``approach`` (and ``options``' other layers) alone."""
    return acting_around_the_tool(obstacles, layers(final_approach=approach, **options), goal_offset)


def test_env_steps_past_a_wall_beside_the_goal_and_stops_at_one_across_the_path():
    env = _approach([_wall_beside], np.array([0.08, 0.0, 0.0]))
    try:
        info = _idle(env)
        assert info["is_success"] and not info["collision"] and env.unwrapped.steps <= 17
        assert set(info["sources"]) == {"final_approach"}  # the idle policy never moved the tool
    finally:
        env.close()
    for approach in (None, FinalApproach()):  # without it, or with the way blocked, the tool stays put
        env = _approach([_wall_across], np.array([0.08, 0.0, 0.0]), approach)
        try:
            info = _idle(env)
            assert not info["is_success"] and not info["collision"] and info["distance"] == pytest.approx(0.08, abs=1e-3)
            assert "final_approach" not in info["sources"]
        finally:
            env.close()


def test_the_final_approach_takes_over_only_while_it_is_on():
    """The goal beside the wall, the policy pushing away from it (-x): through the final
    approach the steps are the final approach's, to the goal; with it off by name the push
    is the policy's and the tool leaves the goal behind."""
    for config, reached in ((ActingConfig().without("detour", "resample"), True),
                            (ActingConfig().without("final_approach", "detour", "resample"), False)):
        env = acting_around_the_tool([_wall_beside], config, np.array([0.08, 0.0, 0.0]))
        try:
            env.reset(seed=0)
            sources = []
            for _ in range(20):
                _, _, terminated, _, info = env.step(np.array([-1, 0, 0, 0, 0, 0], np.float32))
                sources.append(info["acting"]["source"])
                assert info["acting"]["source"] in SOURCES and not info["collision"]
                if terminated:
                    break
            assert info["is_success"] == reached
            assert set(sources) == ({"final_approach"} if reached else {"policy"})
            if not reached:
                assert info["distance"] == pytest.approx(0.08 + 20 * 0.005, abs=2e-3)
        finally:
            env.close()


@pytest.mark.parametrize("give_way", [False, True])
def test_a_final_approach_the_arms_rule_holds_gives_way_to_the_policy_unless_told_not_to(give_way, monkeypatch):
    """The arm's rule stands in for a wrist beside a shelf's board: it refuses every straight
    step. Without ``give_way`` the final approach asks again and again and the arm stays
    held; with it, after the first held step the policy's own steps (+x, at the goal) go
    through and reach the goal."""
    from rayreach.acting.layers import ArmRule
    from rayreach.acting.pipeline import Verdict

    original = ArmRule.veto
    monkeypatch.setattr(ArmRule, "veto", lambda self, command, *rest: Verdict.REFUSE if command.straight
                        else original(self, command, *rest))
    config = dataclasses.replace(ActingConfig().without("detour", "resample"),
                                 final_approach=FinalApproach(give_way=give_way))
    env = acting_around_the_tool([], config, np.array([0.06, 0.0, 0.0]))
    try:
        env.reset(seed=0)
        proposed, sources = [], []
        for _ in range(20):
            _, _, terminated, _, info = env.step(np.array([1, 0, 0, 0, 0, 0], np.float32))
            proposed.append(info["acting"]["proposed"])
            sources.append(info["acting"]["source"])
            if terminated:
                break
        assert proposed[0] == "final_approach" and sources[0] == "held"
        assert info["acting"]["held_by"] == ("" if give_way else "arm_guard")
        if give_way:
            assert set(proposed[1:]) == {"policy"} and info["is_success"] and not info["collision"]
        else:
            assert set(proposed) == {"final_approach"} and set(sources) == {"held"}
            assert info["distance"] == pytest.approx(0.06, abs=1e-3)
    finally:
        env.close()


def _wall_past_the_goal(ee):  # an upright plate across the path 6.5 cm ahead: 3.5 cm past a goal 3 cm ahead
    return ObstacleSpec("box", (ee[0] + 0.065, ee[1], ee[2]), half_extents=(0.002, 0.05, 0.04))


def test_the_shield_lets_the_straight_step_reach_a_goal_nearer_than_anything_seen():
    """The wall is inside the 5 cm shield from the start, so the shield alone holds the tool
    3 cm short; the goal is nearer than the wall, so the straight step reaches it."""
    env = _approach([_wall_past_the_goal], np.array([0.03, 0.0, 0.0]), None, safety=ACTING_SAFETY)
    try:
        obs, _ = env.reset(seed=0)
        assert obs[N_ROBOT_OBS:].min() * env.unwrapped.config.ray_range < ACTING_SAFETY.ray_shield
        info = _idle(env)
        assert not info["collision"] and info["distance"] == pytest.approx(0.03, abs=1e-3)
    finally:
        env.close()
    env = _approach([_wall_past_the_goal], np.array([0.03, 0.0, 0.0]), safety=ACTING_SAFETY)
    try:
        info = _idle(env)
        assert info["is_success"] and not info["collision"] and env.unwrapped.steps <= 7
        assert set(info["sources"]) == {"final_approach"}
    finally:
        env.close()


def test_a_stall_is_too_little_progress_over_the_last_steps():
    approach = FinalApproach(radius=0.1, stall_steps=3, stall_gain=0.01)
    assert not approach.stalled([0.3, 0.3, 0.3])  # not 3 steps yet
    assert approach.stalled([0.3, 0.3, 0.3, 0.295])
    assert not approach.stalled([0.3, 0.3, 0.3, 0.285])
    assert approach.stalled([0.4, 0.3, 0.3, 0.3, 0.3])  # only the last 3 steps count
    assert not FinalApproach(radius=0.1, stall_steps=0).stalled([0.3] * 50)
    np.testing.assert_allclose(approach.towards(np.array([0.03, 0.0, -0.04])), [0.6, 0.0, -0.8, 0, 0, 0])


def test_env_steps_towards_the_goal_after_a_stall_and_not_before():
    """A policy that stands still 10.7 cm from the goal, outside the UR5's 10 cm radius: after
    100 steps without progress the env nudges the tool towards the goal, inside the radius,
    and the final approach finishes; without the stall rule it stands still to the end."""
    for stall_steps, reached in ((0, False), (100, True)):
        env = _approach([], np.array([0.107, 0.0, 0.0]), FinalApproach(stall_steps=stall_steps))
        try:
            info = _idle(env, steps=150)
            assert info["is_success"] == reached and not info["collision"]
            if reached:
                assert 100 < env.unwrapped.steps <= 100 + 22  # 10.7 cm of 5 mm steps
                # the idle policy's zero step leaves the arm still: held, and the policy's
                assert set(info["sources"][:100]) <= IDLE and "stall" in info["sources"][100:]
                assert info["sources"][-1] == "final_approach"
            else:
                assert info["distance"] == pytest.approx(0.107, abs=1e-3)
                assert set(info["sources"]) <= IDLE
        finally:
            env.close()


def test_the_stall_window_and_the_refused_sources_start_again_at_each_goal():
    env = ActingEnv(ReachEnv(robot="ur5", scenario="exp2", goal_tolerance=0.3),
                    layers(final_approach=FinalApproach(stall_steps=2)))
    try:
        _, start = env.reset(seed=0)
        assert env._episode.distances == [start["distance"]]
        env._episode.refused.add("final_approach")  # a held straight step before the goal switched
        _, _, _, _, info = env.step(np.zeros(6, np.float32))
        assert info["goal_index"] == 1 and env._episode.distances == [info["distance"]]
        assert env._episode.refused == set()
    finally:
        env.close()


AXIAL = FinalApproach(radius=0.1, axial_radius=0.13, axial_angle=np.radians(15.0), ee_step=0.005)
DOWN = np.array([0.0, 0.0, -1.0])


@pytest.mark.parametrize("offset,straight", [
    ((0.0, 0.0, -0.12), True),                                      # 12 cm below, along the tool
    ((0.12 * np.sin(np.radians(10)), 0.0, -0.12 * np.cos(np.radians(10))), True),   # 10 deg off the axis
    ((0.12 * np.sin(np.radians(20)), 0.0, -0.12 * np.cos(np.radians(20))), False),  # 20 deg off
    ((0.12, 0.0, 0.0), False),                                      # 12 cm aside
    ((0.0, 0.0, 0.12), False),                                      # 12 cm behind the tool
    ((0.0, 0.0, -0.135), False),                                    # beyond the axial radius
    ((0.09, 0.0, 0.0), True),                                       # within the radius, any way
])
def test_along_the_tools_axis_the_straight_path_starts_farther_out(offset, straight):
    action = AXIAL.action(np.array(offset), NOTHING, DOWN)
    assert (action is not None) == straight
    if straight:  # along the offset, its largest axis a full step
        np.testing.assert_allclose(action[:3], np.array(offset) / np.abs(offset).max(), atol=1e-6)


def test_the_axial_radius_needs_the_tools_direction_and_still_tests_the_path():
    assert AXIAL.action(np.array([0.0, 0.0, -0.12]), NOTHING) is None  # no axis given: the radius alone
    wall = np.array([[0.0, 0.0, -0.06]])  # something seen on the path, 6 cm below
    assert AXIAL.action(np.array([0.0, 0.0, -0.12]), wall, DOWN) is None
    assert dataclasses.replace(AXIAL, axial_radius=None).action(np.array([0.0, 0.0, -0.12]), NOTHING, DOWN) is None


def test_the_env_fills_in_the_robots_radius_unless_one_is_given():
    for robot, radius, axial in (("ur5", 0.1, 0.13), ("kr16", 0.2, None)):
        spec = get_robot(robot)
        env = ActingEnv(ReachEnv(robot=robot, scenario="random"), layers(final_approach=FinalApproach()))
        try:
            applied = env.final_approach
            assert applied.radius == ROBOT_RADII[robot].radius == radius
            assert applied.axial_radius == ROBOT_RADII[robot].axial_radius == axial
            assert (applied.ee_step, applied.rot_step) == (spec.ee_step, spec.rot_step)
            assert (applied.tool_length, applied.tool_radius) == (spec.tool.length, spec.tool.radius)
            given = ActingEnv(env.env, layers(final_approach=FinalApproach(radius=0.15, axial_radius=0.2)))
            assert given.final_approach.radius == 0.15 and given.final_approach.axial_radius == 0.2
            assert ActingEnv(env.env, layers()).final_approach is None
        finally:
            env.close()
    with pytest.raises(ValueError, match="radius"):
        FinalApproach().action(np.array([0.03, 0.0, 0.0]), NOTHING)


def test_env_steps_straight_from_farther_with_a_larger_radius():
    for radius, reached in ((None, False), (0.15, True)):  # the UR5's own radius is 0.1 m
        env = _approach([], np.array([0.13, 0.0, 0.0]), FinalApproach(radius))
        try:
            info = _idle(env)
            assert info["is_success"] == reached and not info["collision"]
        finally:
            env.close()


def _cover_over_the_path(ee):  # a flat plate 6 cm above the tip, its edge 4 cm ahead: in the tool's way
    return ObstacleSpec("box", (ee[0] + 0.10, ee[1], ee[2] + 0.06), half_extents=(0.06, 0.05, 0.003))


def test_env_keeps_the_tool_body_off_a_plate_the_tips_path_passes_under():
    env = exp1_around_the_tool([_cover_over_the_path], np.array([0.08, 0.0, 0.0]))
    try:  # driven straight at the goal, the (downward) tool hits the plate
        env.reset(seed=0)
        np.testing.assert_allclose(env.ee_rot[:, 2], [0.0, 0.0, -1.0], atol=1e-6)
        for _ in range(16):
            _, _, terminated, _, info = env.step(np.array([1, 0, 0, 0, 0, 0], np.float32))
            if terminated:
                break
        assert info["collision"]
    finally:
        env.close()
    env = _approach([_cover_over_the_path], np.array([0.08, 0.0, 0.0]), FinalApproach(turn=False))
    try:
        info = _idle(env)
        assert not info["collision"] and info["distance"] == pytest.approx(0.08, abs=1e-3)
    finally:
        env.close()


def test_env_turns_the_tool_under_a_plate_its_back_would_strike_and_reaches_the_goal():
    """The plate of the test above: turned about its tip towards the path (through the
    shield, which keeps the final approach's turn), the tool slides in under the plate;
    PyBullet finds no contact on the way."""
    env = _approach([_cover_over_the_path], np.array([0.08, 0.0, 0.0]))
    try:
        info = _idle(env, steps=400)
        assert info["is_success"] and not info["collision"]
        assert env.unwrapped.ee_rot[0, 2] > 0.5  # the tool leans towards the goal
    finally:
        env.close()


def test_env_tool_axis_is_where_pybullet_has_the_tool():
    env = exp1_around_the_tool([_cover_over_the_path])
    try:
        env.reset(seed=0)
        env.step(np.array([0.3, -0.2, 0.5, 1.0, -0.5, 0.2], np.float32))  # a turned tool
        flange, _ = env.scene.link_pose("rayreach_tool")
        np.testing.assert_allclose(env.ee_pos - env.spec_robot.tool.length * env.ee_rot[:, 2], flange, atol=1e-6)
    finally:
        env.close()


def _acting_env(env) -> ActingEnv | None:
    """The ``ActingEnv`` in ``env``'s chain of wrappers, if any."""
    while not isinstance(env, ActingEnv):
        if not hasattr(env, "env"):
            return None
        env = env.env
    return env


def test_training_envs_act_with_the_layers_only_when_asked():
    """With ``acting_layers`` the training env acts through ``ActingConfig.training()``: the
    shield, workspace guard and arm's rule of the shipped stack; the layers that replace the
    policy's action (final approach, detour, slide) stay out."""
    for acting in (False, True):
        config = TrainConfig(robot="ur5", envs=32, acting_layers=acting, shield_weight=-0.1)
        monitored = make_env_fn(config, 0)()
        try:
            wrapper = _acting_env(monitored)
            assert (wrapper is not None) == acting
            assert monitored.unwrapped.config.rewards.shielded == -0.1
            if acting:
                assert wrapper.config == ActingConfig.training()
                assert wrapper.final_approach is None and wrapper.config.detour is None
                assert wrapper.config.safety.active and wrapper.config.safety.slide == 0.0
                assert wrapper.config.layers == ("ray_shield", "workspace_guard", "arm_guard")
        finally:
            monitored.close()


def _box_behind(ee):  # its +x face 9 cm to the -x of the tool point
    return ObstacleSpec("box", (ee[0] - 0.14, ee[1], ee[2]), half_extents=(0.05, 0.15, 0.15))


@pytest.mark.parametrize("scene, goal_offset, push, replaced_by", [
    ([_wall_beside], (0.08, 0.0, 0.0), (0.0, 0.0, 0.0), "final_approach"),  # an idle policy beside the goal
    ([_box_behind], (0.0, 0.15, 0.0), (-1.0, 0.0, 0.0), "slide"),  # a push held at a box, the goal aside
])
def test_training_layers_never_replace_the_policys_action(scene, goal_offset, push, replaced_by):
    """Where the shipped stack's final approach takes over and where the slide (an option)
    does, ``ActingConfig.training()`` leaves every step the policy's, or held."""
    action = np.r_[push, 0.0, 0.0, 0.0].astype(np.float32)
    for config, kept in ((SLIDING_STACK.without("resample"), False), (ActingConfig.training(), True)):
        env = acting_around_the_tool(scene, config, np.array(goal_offset))
        try:
            env.reset(seed=0)
            sources = set()
            for _ in range(60):
                _, _, terminated, truncated, info = env.step(action)
                sources.add(info["acting"]["source"])
                if terminated or truncated:
                    break
            assert not info["collision"]
            assert sources <= set(SOURCES)
            assert (sources <= {"policy", "held"}) == kept, sources
            assert (replaced_by in sources) == (not kept), sources
        finally:
            env.close()


@pytest.mark.parametrize("actor, features", [(False, False), (True, False)])
def test_set_trainable_moves_only_what_it_frees(actor, features):
    """Critic warm-up (actor and extractor held) and a part with the extractor held: one
    PPO update changes exactly the parameters left trainable."""
    from stable_baselines3 import PPO

    from rayreach.learning.train import build_model, build_vec_env

    config = TrainConfig(robot="ur5", envs=1, workers=1, n_steps=64, batch_size=32, n_epochs=1)
    venv = build_vec_env(config)
    try:
        model: PPO = build_model(config, venv, None)
        policy = model.policy
        critic = {id(q) for m in (policy.mlp_extractor.value_net, policy.value_net) for q in m.parameters()}
        extractor = {id(q) for q in policy.features_extractor.parameters()}
        set_trainable(policy, actor=actor, features=features)
        before = {name: q.detach().clone() for name, q in policy.named_parameters()}
        model.learn(64)
        for name, q in policy.named_parameters():
            changed = not np.allclose(before[name].numpy(), q.detach().numpy())
            expected = id(q) in critic or (actor and id(q) not in extractor)
            assert changed == expected, name
        set_trainable(policy)
        assert all(q.requires_grad for q in policy.parameters())
    finally:
        venv.close()


@pytest.mark.parametrize("policy_step", [False, True])
def test_a_straight_step_lets_the_orientation_go_when_ik_cannot_keep_it(policy_step, monkeypatch):
    """With an IK that cannot reach any full pose (a stand-in for a tool orientation out of
    reach), the final approach still moves the tip to the goal, solving for the position
    alone; the policy's own steps get no such fallback, and the unconverged 6-D result
    (here, the unchanged configuration) is all they get."""
    goal = np.array([0.03, 0.0, 0.0])
    env = _approach([], goal, None if policy_step else FinalApproach())
    reach = env.unwrapped
    try:
        env.reset(seed=0)
        real_ik = reach.kin.ik
        asked = []

        def pose_out_of_reach(target_pos, target_rot, q, params, start_frames=None):
            asked.append(target_rot is None)
            if target_rot is None:
                return real_ik(target_pos, None, q, params, start_frames=start_frames)
            stuck = real_ik(reach.ee_pos, reach.ee_rot, q, params, start_frames=start_frames)
            return dataclasses.replace(stuck, converged=False)

        monkeypatch.setattr(reach.kin, "ik", pose_out_of_reach)
        start = reach.ee_pos.copy()
        _, _, _, _, info = env.step(np.array([1, 0, 0, 0, 0, 0], np.float32))
        if policy_step:
            assert asked == [False] and np.linalg.norm(reach.ee_pos - start) < 1e-4
            assert info["acting"]["proposed"] == "policy"
        else:
            assert asked == [False, True]
            assert reach.ee_pos[0] - start[0] == pytest.approx(0.005, abs=2e-4)  # a full step along x
            assert info["acting"]["source"] == "final_approach"
    finally:
        env.close()


def test_distances_to_a_segment_match_hand_geometry():
    """Beside the segment, past either end, and a zero segment (a point)."""
    points = np.array([[0.5, 0.3, 0.0], [-0.3, 0.4, 0.0], [2.0, 0.0, 0.0]])
    np.testing.assert_allclose(distances_to_segment(points, np.zeros(3), np.array([1.0, 0.0, 0.0])), [0.3, 0.5, 1.0])
    np.testing.assert_allclose(distances_to_segment(points, np.zeros(3), np.zeros(3)), [np.hypot(0.5, 0.3), 0.5, 2.0])
