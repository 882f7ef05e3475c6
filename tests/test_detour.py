"""The detour a stalled policy is taken on: planned on the rays' hits alone, read from the
episode's ray memory (rayreach.acting.detour), then acting through ``ActingEnv``."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from exp1_scenes import acting_around_the_tool, layers
from rayreach.acting import ActingEnv
from rayreach.acting.detour import Detour, DetourState
from rayreach.acting.final_approach import FinalApproach
from rayreach.acting.layers import DetourStep
from rayreach.acting.memory import RayMemory
from rayreach.acting.shield import ACTING_SAFETY, SafetyLayer
from rayreach.env.perception import Perception
from rayreach.sim.geometry import distances_to_segment

DOWN = np.array([0.0, 0.0, -1.0])
LOW, HIGH = np.array([-0.4, -0.3, -0.2]), np.array([0.4, 0.3, 0.35])
TOOL_LENGTH, TOOL_RADIUS, ARRIVE, RANGE = 0.13, 0.02, 0.1, 0.4


def _state(detour: Detour = Detour()) -> DetourState:
    """A detour over an empty ray memory (``_look_at`` adds scans to it)."""
    return DetourState(detour, RayMemory(), TOOL_LENGTH, TOOL_RADIUS, ARRIVE, RANGE, LOW, HIGH)


def _act(state: DetourState, ee, goal, distances) -> np.ndarray | None:
    """The detour's action after ``len(distances) - 1`` steps towards a goal current since the start."""
    return state.action(len(distances) - 1, np.asarray(ee), np.asarray(goal), DOWN, distances)


def _look_at(state: DetourState, origin, points, beyond: float = 0.0) -> None:
    """One step's rays from ``origin`` to each of ``points`` (hitting them), or ``beyond`` m
    past them (``RANGE``: seeing nothing)."""
    points = np.atleast_2d(np.asarray(points, float))
    offsets = points - np.asarray(origin, float)
    lengths = np.linalg.norm(offsets, axis=1)
    directions = offsets / lengths[:, None]
    seen = np.minimum(lengths + beyond, RANGE)
    scan = Perception(step=len(state.memory.scans), q=np.zeros(6), ee_position=np.asarray(origin, float),
                      ee_rotation=np.eye(3), goal=np.zeros(3), origins=np.tile(origin, (len(points), 1)),
                      directions=directions, lengths=seen, fractions=seen / RANGE, workspace_low=LOW,
                      workspace_high=HIGH)
    state.memory.add(scan, moved=True)


def _wall(x: float = 0.0) -> np.ndarray:
    """An upright plate across x, 0.2 m wide and 0.1 m tall, as 5 mm samples."""
    y, z = np.meshgrid(np.arange(-0.1, 0.1001, 0.005), np.arange(-0.05, 0.0501, 0.005))
    return np.stack([np.full(y.size, x), y.ravel(), z.ravel()], axis=1)


def test_a_plan_goes_round_what_was_seen_with_the_tool_and_arm_clear_of_it():
    state = _state()
    start, goal = np.array([0.15, 0.0, 0.0]), np.array([-0.15, 0.0, 0.0])
    wall = _wall()
    _look_at(state, start, wall)
    assert len(state.seen()) > 100
    path = state.plan(start, goal, DOWN)
    assert path is not None
    d = state.detour
    assert np.linalg.norm(path[0] - start) < 0.1 and np.linalg.norm(path[-1] - goal) < ARRIVE
    assert np.all(np.linalg.norm(np.diff(path, axis=0), axis=1) <= np.sqrt(3) * d.cell + 1e-9)  # neighbours
    # the tool and the arm behind it (upwards from the tip) keep the clearance, to within the
    # grid's rounding, wherever the path has left the goal's sphere
    body = -(TOOL_LENGTH + d.behind) * DOWN
    outside = path[np.linalg.norm(path - goal, axis=1) >= ARRIVE - d.cell]
    nearest = min(distances_to_segment(wall, tip, body).min() for tip in outside)
    assert nearest >= d.clearance + TOOL_RADIUS - d.cell
    assert np.all(np.all((path >= LOW) & (path <= HIGH), axis=1))


def test_an_enclosed_start_has_no_way_round_and_leaves_it_to_the_policy():
    state = _state(Detour(stall_steps=2))
    start, goal = np.zeros(3), np.array([0.0, 0.25, 0.0])
    u = np.linspace(-1, 1, 25)
    a, b = np.meshgrid(u, u)
    sphere = np.stack([a.ravel(), b.ravel(), np.ones(a.size)], axis=1)
    box = np.concatenate([np.roll(sphere * s, k, axis=1) for s in (1, -1) for k in range(3)]) * 0.12
    _look_at(state, start, box)
    assert state.plan(start, goal, DOWN) is None
    distances = [0.25] * 4
    assert _act(state, start, goal, distances) is None and not state.active


def test_a_ray_passing_through_a_remembered_hit_forgets_it_and_one_ending_there_keeps_it():
    origin, point = np.zeros(3), np.array([0.2, 0.0, 0.0])
    for beyond, kept in ((0.0, True), (DetourState.PASSED / 2, True), (0.1, False), (1.0, False)):
        state = _state()
        _look_at(state, origin, point)
        _look_at(state, origin + [0.0, 0.001, 0.0], point + [0.0, 0.001, 0.0], beyond=beyond)
        remembered = np.linalg.norm(state.seen() - point, axis=1) < 0.002
        assert remembered.any() == kept, beyond
    state = _state()  # seen, passed through, seen again: remembered
    for beyond in (0.0, 1.0, 0.0):
        _look_at(state, origin, point, beyond=beyond)
    np.testing.assert_allclose(state.seen(), [point])
    state = _state()  # a ray passing 1 cm beside a hit does not show it gone
    _look_at(state, origin, point)
    _look_at(state, origin, point + [0.0, 0.01, 0.0], beyond=1.0)
    np.testing.assert_allclose(state.seen(), [point])


def test_a_hit_is_remembered_once_per_voxel():
    state = _state()
    _look_at(state, np.zeros(3), [[0.2, 0.0, 0.0], [0.2, 0.001, 0.001], [0.2, 0.05, 0.0]])
    _look_at(state, np.zeros(3), [[0.2, 0.002, 0.0]])
    assert len(state.seen()) == 2


def test_the_memory_is_read_as_it_grows():
    """The detour reads the episode's one ray memory: scans added after a look are taken in at
    the next (a hit that a later ray passed through stays gone)."""
    state = _state()
    origin, point = np.zeros(3), np.array([0.2, 0.0, 0.0])
    _look_at(state, origin, point)
    np.testing.assert_allclose(state.seen(), [point])
    _look_at(state, origin, point, beyond=1.0)  # passed through: forgotten
    assert len(state.seen()) == 0
    _look_at(state, origin, point + [0.0, 0.05, 0.0])
    np.testing.assert_allclose(state.seen(), [point + [0.0, 0.05, 0.0]])


def test_the_detour_starts_after_a_stall_steps_along_its_path_and_ends_near_the_goal():
    state = _state(Detour(stall_steps=3))
    ee, goal = np.array([0.15, 0.0, 0.0]), np.array([-0.15, 0.0, 0.0])
    _look_at(state, ee, _wall())
    assert _act(state, ee, goal, [0.3, 0.3, 0.3]) is None  # 3 steps not yet
    assert _act(state, ee, goal, [0.4, 0.3, 0.3, 0.3]) is None  # progress
    assert state.action(500, ee, goal, DOWN, [0.3, 0.3]) is None  # a new goal's window is not full yet
    action = _act(state, ee, goal, [0.3] * 4)
    assert state.active and action is not None
    assert np.linalg.norm(action[:3]) == pytest.approx(1.0) and not action[3:].any()
    near = goal + [0.05, 0.0, 0.0]
    assert _act(state, near, goal, [0.3] * 5) is None and not state.active


def test_a_detour_the_arm_does_not_follow_hands_back_to_the_policy_for_a_stall_window():
    state = _state(Detour(stall_steps=3, held_steps=2))
    ee, goal = np.array([0.15, 0.0, 0.0]), np.array([-0.15, 0.0, 0.0])
    distances = [0.3] * 4
    assert _act(state, ee, goal, distances) is not None
    for expected in (True, False):  # held once, held twice: given up
        distances.append(0.3)
        assert (_act(state, ee, goal, distances) is not None) == expected
    for _ in range(2):  # the stall must last a whole window (3 steps) again
        distances.append(0.3)
        assert _act(state, ee, goal, distances) is None
    distances.append(0.3)
    assert _act(state, ee, goal, distances) is not None


@pytest.mark.parametrize("field, value", [("stall_steps", 0), ("replan_steps", 2.5), ("held_steps", -1),
                                          ("cell", 0.0), ("reach", -0.1), ("clearance", -0.01),
                                          ("behind", float("nan"))])
def test_bad_settings_are_refused_by_name(field, value):
    with pytest.raises(ValueError, match=field):
        Detour(**{field: value})


def test_on_the_detours_steps_the_shield_holds_off_only_what_is_nearer_than_the_clearance():
    """A path keeps ``clearance`` from what was seen, so a wider shield would refuse the path's
    own steps past a slot's plates; a hit nearer than the clearance is still held off."""
    detour = Detour(clearance=0.04)
    layer = detour.shield(ACTING_SAFETY)
    assert layer.ray_shield == 0.04 and dataclasses.replace(layer, ray_shield=ACTING_SAFETY.ray_shield) == ACTING_SAFETY
    ee, low, high = np.zeros(3), -np.ones(3), np.ones(3)
    step = np.array([0.005, 0.0, 0.0, 0.0, 0.0, 0.0])
    ahead = np.array([[1.0, 0.0, 0.0]])
    for seen, kept in ((0.045, 0.005), (0.035, 0.0)):
        assert layer.filter(step, ee, low, high, np.array([seen]), ahead)[0] == pytest.approx(kept)
        assert ACTING_SAFETY.filter(step, ee, low, high, np.array([seen]), ahead)[0] == pytest.approx(0.0)
    narrow = dataclasses.replace(ACTING_SAFETY, ray_shield=0.02)
    assert detour.shield(narrow).ray_shield == 0.02  # never widened
    assert detour.shield(SafetyLayer()) == SafetyLayer()  # off stays off


def _idle(env: ActingEnv, steps: int = 1024) -> dict:
    """Steps with a zero action; the last info, with every step's source under ``"sources"``."""
    env.reset(seed=0)
    sources = []
    for _ in range(steps):
        _, _, terminated, truncated, info = env.step(np.zeros(6, np.float32))
        sources.append(info["acting"]["source"])
        if terminated or truncated:
            break
    return {**info, "sources": sources}


def _plate_between(ee):  # exp1's plate, between the tool and a goal 0.3 m beyond it
    from rayreach.scenarios.schema import ObstacleSpec
    return ObstacleSpec("box", (ee[0] - 0.15, ee[1], ee[2]), half_extents=(0.002, 0.1, 0.05))


def test_env_takes_a_still_policy_round_a_plate_to_the_goal_without_contact():
    """A policy that stands still in front of a plate, the goal behind it: the detour plans
    round what the rays see of the plate and the final approach finishes, with no contact
    PyBullet can find; without it the arm stands still to the end."""
    for detour, reached in ((None, False), (Detour(), True)):
        config = layers(final_approach=FinalApproach(), safety=ACTING_SAFETY, detour=detour)
        env = acting_around_the_tool([_plate_between], config, np.array([-0.3, 0.0, 0.0]))
        try:
            info = _idle(env)
            assert info["is_success"] == reached and not info["collision"]
            sources = info["sources"]
            assert ("detour" in sources) == reached
            if reached:
                steps = env.unwrapped.steps
                assert Detour.stall_steps < steps < 1024
                first = sources.index("detour")  # the policy's (still) steps until the stall
                assert first >= Detour.stall_steps and set(sources[:first]) <= {"policy", "held"}
                assert sources[-1] == "final_approach"  # which finishes
                assert any(isinstance(c, DetourStep) for c in env.components)
        finally:
            env.close()
