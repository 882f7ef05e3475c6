"""The safety layer: each rule on its own, the shield's memory (``remembered_rays``) over
constructed scans, then acting through ``ActingEnv`` against PyBullet's contacts."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from exp1_scenes import SLIDING, SLIDING_STACK, acting_around_the_tool, layers
from rayreach.acting import ActingConfig, ActingEnv
from rayreach.acting.memory import RayMemory
from rayreach.acting.shield import (ACTING_SAFETY, LOST, MARGIN, SLIDE, SafetyLayer, nearest_direction_in_cone,
                                    nearest_in_cone, remembered_rays)
from rayreach.env.perception import Perception
from rayreach.env.reach import ReachEnv
from rayreach.env.rewards import RewardWeights
from rayreach.scenarios.schema import ObstacleSpec

FAR = np.full(3, 0.4)
X, Y, Z = np.eye(3)
LOW, HIGH = np.array([-0.4, 0.3, 0.2]), np.array([0.4, 0.7, 0.5])
INSIDE = np.array([0.0, 0.5, 0.35])


def test_shield_drops_only_the_motion_towards_what_a_near_ray_sees():
    shield = SafetyLayer(ray_shield=0.05)
    delta = np.array([0.005, 0.003, -0.004, 0.002, 0.0, 0.001])
    directions = np.stack((X, Y, Z))
    out = shield.filter(delta, INSIDE, LOW, HIGH, np.array([0.03, 0.4, 0.4]), directions)
    np.testing.assert_allclose(out, [0.0, 0.003, -0.004, 0.0, 0.0, 0.0])
    away = shield.filter(-delta, INSIDE, LOW, HIGH, np.array([0.03, 0.4, 0.4]), directions)
    np.testing.assert_allclose(away[:3], -delta[:3])  # moving away from it is left alone
    np.testing.assert_allclose(shield.filter(delta, INSIDE, LOW, HIGH, FAR, directions), delta)


def test_shield_keeps_a_rotation_tested_against_the_rays_already():
    """The final approach's turn (``keep_rotation``) passes a near ray; any other rotation
    is dropped with it."""
    shield = SafetyLayer(ray_shield=0.05)
    turn = np.array([0.0, 0.0, 0.0, 0.0, -0.005, 0.0])
    near = np.array([0.03, 0.4, 0.4])
    directions = np.stack((X, Y, Z))
    np.testing.assert_allclose(shield.filter(turn, INSIDE, LOW, HIGH, near, directions, keep_rotation=True), turn)
    np.testing.assert_allclose(shield.filter(turn, INSIDE, LOW, HIGH, near, directions), np.zeros(6))


def test_shield_handles_an_oblique_ray_and_several_near_rays():
    shield = SafetyLayer(ray_shield=0.05)
    diagonal = (X + Y) / np.sqrt(2)
    out = shield.filter(np.array([0.005, 0, 0, 0, 0, 0]), INSIDE, LOW, HIGH,
                        np.array([0.01, 0.4]), np.stack((diagonal, Z)))
    np.testing.assert_allclose(out[:3], [0.0025, -0.0025, 0.0], atol=1e-12)
    assert out[:3] @ diagonal == pytest.approx(0.0, abs=1e-12)
    both = shield.filter(np.array([0.005, 0.005, 0.005, 0, 0, 0]), INSIDE, LOW, HIGH,
                         np.array([0.02, 0.04, 0.4]), np.stack((X, Y, Z)))
    np.testing.assert_allclose(both[:3], [0.0, 0.0, 0.005])


def test_no_near_ray_is_approached_when_the_projections_interact():
    """Two near rays 135 degrees apart: one projection each would leave motion towards the
    nearer; so would a bound the tool is at, zeroing an axis after the shield."""
    shield = SafetyLayer(ray_shield=0.05)
    a, b = X, np.array([-1.0, 1.0, 0.0]) / np.sqrt(2)
    out = shield.filter(np.array([0.005, 0.0, 0.0, 0, 0, 0]), INSIDE, LOW, HIGH,
                        np.array([0.01, 0.02]), np.stack((a, b)))
    assert out[:3] @ a <= 1e-9 and out[:3] @ b <= 1e-9
    both = SafetyLayer(workspace_guard=0.01, ray_shield=0.05)
    ahead_below = np.array([1.0, 0.0, -1.0]) / np.sqrt(2)
    at_ceiling = np.array([0.0, 0.5, 0.495])
    out = both.filter(np.array([0.005, 0.0, 0.0, 0, 0, 0]), at_ceiling, LOW, HIGH,
                      np.array([0.02]), ahead_below[None])
    assert out[:3] @ ahead_below <= 1e-9
    assert out[2] <= 0.0


def _dykstra(move: np.ndarray, normals: np.ndarray, rounds: int) -> np.ndarray:
    """Reference: Dykstra's alternating projections, which converge to the nearest point of
    an intersection of half-spaces (plain alternating projections need not)."""
    x, corrections = move.copy(), np.zeros_like(normals)
    for _ in range(rounds):
        for i, n in enumerate(normals):
            y = x + corrections[i]
            x = y - max(0.0, float(y @ n)) * n
            corrections[i] = y - x
    return x


def test_nearest_in_cone_is_the_projection_dykstra_converges_to():
    rng = np.random.default_rng(0)
    for k in (1, 2, 3, 5, 8):
        for _ in range(6):
            normals = rng.normal(size=(k, 3))
            normals /= np.linalg.norm(normals, axis=1, keepdims=True)
            move = rng.normal(size=3) * 0.005
            out = nearest_in_cone(move, normals)
            assert np.all(normals @ out <= 1e-12)
            np.testing.assert_allclose(out, _dykstra(move, normals, 5000), atol=2e-8)  # of a 5 mm step


def test_a_ray_and_the_ceiling_leave_the_step_along_the_edge_they_share():
    """The tool just inside the guard's band under the ceiling, something seen 4.8 cm away
    40 degrees off straight down, the goal below and beyond (a traced UR5 timeout): the step
    kept runs along the line the two planes share. Projecting onto one plane after the other
    left 2e-8 m of motion towards the ray after 20 rounds, and the layer stopped the tool."""
    layer = SafetyLayer(workspace_guard=0.01, ray_shield=0.05)
    ray = np.array([-0.64, 0.06, -0.76]) / np.linalg.norm([-0.64, 0.06, -0.76])
    step = np.array([-0.00386, -0.00216, -0.00234])
    out = layer.filter(np.r_[step, 0.0, 0.0, 0.0], np.array([0.0, 0.42, 0.4901]), LOW, HIGH,
                       np.array([0.048]), ray[None])[:3]
    edge = np.cross(ray, Z) / np.linalg.norm(np.cross(ray, Z))
    np.testing.assert_allclose(out, (step @ edge) * edge, atol=1e-15)
    assert np.linalg.norm(out) > 0.002


def test_a_known_travel_shorter_than_every_ray_lets_the_motion_through():
    """The final approach's straight path ends at the goal: when every ray sees farther than
    that, the shield has nothing to keep the tool off; otherwise it acts as without it."""
    shield = SafetyLayer(ray_shield=0.05)
    delta = np.array([0.005, 0.0, 0.0, 0.0, 0.0, 0.0])
    distances, directions = np.array([0.03, 0.4]), np.stack((X, Y))
    np.testing.assert_allclose(shield.filter(delta, INSIDE, LOW, HIGH, distances, directions, travel=0.02), delta)
    for travel in (None, 0.03, 0.06):
        np.testing.assert_allclose(shield.filter(delta, INSIDE, LOW, HIGH, distances, directions, travel=travel),
                                   np.zeros(6))
    guard = SafetyLayer(workspace_guard=0.01, ray_shield=0.05)  # the guard still holds the bound
    at_bound = HIGH - [0.012, 0.2, 0.1]
    np.testing.assert_allclose(guard.filter(delta, at_bound, LOW, HIGH, distances, directions, travel=0.02), 0.0)


def test_slide_takes_the_goal_step_once_the_push_is_held():
    """A push straight at a near wall (the X ray at 3 cm) is held; with a slide the layer
    steps towards the goal instead, less its part towards the wall."""
    layer = SafetyLayer(ray_shield=0.05, slide=0.1)
    push = np.array([0.005, 0.0, 0.0, 0.0, 0.0, 0.0])
    distances, directions = np.array([0.03, 0.4]), np.stack((X, Y))
    goal_step = np.array([0.0035, 0.0035, 0.0])
    out = layer.filter(push, INSIDE, LOW, HIGH, distances, directions, towards_goal=goal_step)
    np.testing.assert_allclose(out, [0.0, 0.0035, 0.0, 0.0, 0.0, 0.0])
    for held in (layer.filter(push, INSIDE, LOW, HIGH, distances, directions),  # no goal step given
                 SafetyLayer(ray_shield=0.05).filter(push, INSIDE, LOW, HIGH, distances, directions,
                                                     towards_goal=goal_step)):  # slide off
        np.testing.assert_allclose(held, np.zeros(6))
    oblique = np.array([0.005, 0.001, 0.0, 0.0, 0.0, 0.0])  # a fifth of it is left: no slide
    np.testing.assert_allclose(layer.filter(oblique, INSIDE, LOW, HIGH, distances, directions, towards_goal=goal_step),
                               [0.0, 0.001, 0.0, 0.0, 0.0, 0.0])


def test_guard_stops_at_a_bound_and_lets_the_tool_slide_along_it():
    guard = SafetyLayer(workspace_guard=0.01)
    near_top = np.array([0.0, 0.5, 0.487])
    out = guard.filter(np.array([0.005, -0.005, 0.005, 0.001, 0, 0]), near_top, LOW, HIGH, FAR, np.eye(3))
    np.testing.assert_allclose(out, [0.005, -0.005, 0.0, 0.001, 0, 0])
    down = guard.filter(np.array([0, 0, -0.005, 0, 0, 0]), near_top, LOW, HIGH, FAR, np.eye(3))
    assert down[2] == -0.005


def test_negative_settings_are_refused():
    with pytest.raises(ValueError, match="ray_shield must be >= 0"):
        SafetyLayer(ray_shield=-0.1)
    with pytest.raises(ValueError, match="workspace_guard must be >= 0"):
        SafetyLayer(workspace_guard=-0.01)
    with pytest.raises(ValueError, match="slide must be >= 0"):
        SafetyLayer(slide=-0.1)
    with pytest.raises(ValueError, match="slide is a share"):
        SafetyLayer(slide=1.5)


RANGE = 0.4


def _scan(ee, origins, directions, lengths) -> Perception:
    """A constructed perception: rays (world) from ``origins`` along ``directions``, seeing
    ``lengths`` m (``RANGE``: nothing), with the end effector at ``ee``."""
    lengths = np.asarray(lengths, dtype=float)
    return Perception(step=0, q=np.zeros(6), ee_position=np.asarray(ee, dtype=float), ee_rotation=np.eye(3),
                      goal=np.zeros(3), origins=np.asarray(origins, dtype=float),
                      directions=np.asarray(directions, dtype=float), lengths=lengths, fractions=lengths / RANGE,
                      workspace_low=LOW, workspace_high=HIGH)


def _seen_from(memory: RayMemory, steps: int, ee, origins, directions, lengths, reach: float = 0.05):
    """Add the scan to ``memory`` and read the shield's rays from it, remembering ``steps`` scans."""
    memory.add(_scan(ee, origins, directions, lengths), moved=True)
    return remembered_rays(memory.now, memory.before(steps), reach)


def test_remembered_rays_give_back_what_a_ray_saw_from_where_its_origin_is_now():
    """A ray from 2 cm beside the tool point saw a point 3 cm ahead of it; the tool then moved
    1 cm and the ray sees nothing. The memory returns the point as a ray from the origin's
    new place: 4 cm long here, as plain geometry says."""
    memory = RayMemory()
    origin, direction = np.array([[0.02, 0.0, 0.0]]), np.array([[1.0, 0.0, 0.0]])
    far = np.array([RANGE])
    distances, directions = _seen_from(memory, 2, np.zeros(3), origin, direction, [0.03])
    assert distances.tolist() == [0.03]  # nothing remembered yet
    moved = np.array([-0.01, 0.0, 0.0])
    distances, directions = _seen_from(memory, 2, moved, origin + moved, direction, far)
    np.testing.assert_allclose(distances, [0.4, 0.04])
    np.testing.assert_allclose(directions, [[1, 0, 0], [1, 0, 0]])
    sideways = np.array([0.0, 0.03, 0.0])  # the point is now sqrt(0.03^2 + 0.03^2) from the origin
    distances, directions = _seen_from(memory, 2, sideways, origin + sideways, direction, far)
    np.testing.assert_allclose(distances, [0.4, np.hypot(0.03, 0.03)])
    np.testing.assert_allclose(directions[1], np.array([1.0, -1.0, 0.0]) / np.sqrt(2))
    distances, _ = _seen_from(memory, 2, sideways, origin + sideways, direction, far)
    assert distances.tolist() == [0.4]  # two steps on, forgotten
    first = RayMemory()
    first.add(_scan(np.zeros(3), origin, direction, [0.03]), moved=True)
    first.add(_scan(moved, origin + moved, direction, far), moved=True)
    assert first.before(0) == []  # no memory: the current rays alone
    assert remembered_rays(first.now, first.before(0), 0.05)[0].tolist() == [0.4]


def test_remembered_rays_keep_only_hits_a_step_could_bring_within_the_shield():
    memory = RayMemory()
    origins, directions = np.zeros((2, 3)), np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    _seen_from(memory, 5, np.zeros(3), origins, directions, [0.05 + MARGIN - 1e-4, 0.2])
    closer = np.array([MARGIN, 0.0, 0.0])  # the first point is now just inside 5 cm
    distances, _ = _seen_from(memory, 5, closer, origins + closer, directions, np.full(2, RANGE))
    assert len(distances) == 3 and distances[2] == pytest.approx(0.05 - 1e-4)


def test_remembered_rays_leave_what_the_rays_still_see_to_them():
    """The same point seen again (within ``LOST``) is the current rays' to hold off; only a
    point no ray hits any more comes back from the memory."""
    memory = RayMemory()
    origin, direction = np.zeros((1, 3)), np.array([[1.0, 0.0, 0.0]])
    _seen_from(memory, 3, np.zeros(3), origin, direction, [0.03])
    step = np.array([0.0, LOST / 2, 0.0])  # the ray now hits the face half LOST aside
    distances, _ = _seen_from(memory, 3, step, origin + step, direction, [0.03])
    assert distances.tolist() == [0.03]
    gone = 3 * step  # the ray passed the face's edge: both remembered points are out of sight
    distances, _ = _seen_from(memory, 3, gone, origin + gone, direction, [RANGE])
    np.testing.assert_allclose(distances, [0.4, np.hypot(0.03, 3 * step[1]), np.hypot(0.03, 2 * step[1])])


def test_allows_checks_a_realised_step_against_the_filters_rules():
    layer = SafetyLayer(workspace_guard=0.01, ray_shield=0.05)
    ray = np.array([[-1.0, 0.0, 0.0]])
    middle = np.array([0.0, 0.5, 0.3])
    assert layer.allows(np.array([0.0, 0.005, 0.0]), middle, LOW, HIGH, np.array([0.03]), ray)
    assert not layer.allows(np.array([-0.001, 0.005, 0.0]), middle, LOW, HIGH, np.array([0.03]), ray)
    assert layer.allows(np.array([-0.001, 0.005, 0.0]), middle, LOW, HIGH, np.array([0.3]), ray)  # far: no rule
    assert layer.allows(np.array([-0.00005, 0.005, 0.0]), middle, LOW, HIGH, np.array([0.03]), ray)  # within 0.1 mm


def _near_box(ee):  # its +x face 5 cm to the -x of the tool point; the nearest ray reads 3 cm
    return ObstacleSpec("box", (ee[0] - 0.10, ee[1], ee[2]), half_extents=(0.05, 0.15, 0.15))


@pytest.mark.parametrize("converged", [False, True])
def test_an_unconverged_ik_step_towards_what_the_rays_see_is_not_taken(converged, monkeypatch):
    """The layer lets a sideways step through; IK, failing to converge, would put the tool
    2 mm nearer the box the rays see 3 cm away. The arm holds still instead. A result IK
    reports as converged is taken as it comes: it is the step asked for, within IK's 0.1 mm."""
    env = acting_around_the_tool([_near_box], layers(safety=ACTING_SAFETY))
    reach = env.unwrapped
    try:
        env.reset(seed=0)
        real_ik = reach.kin.ik

        def drifting_ik(target_pos, target_rot, q, params, start_frames=None):
            drifted = real_ik(np.asarray(target_pos) + np.array([-0.002, 0.0, 0.0]), target_rot, q, params,
                              start_frames=start_frames)
            return dataclasses.replace(drifted, converged=converged)

        monkeypatch.setattr(reach.kin, "ik", drifting_ik)
        before, q = reach.ee_pos.copy(), reach.q.copy()
        _, _, _, _, info = env.step(np.array([0, 1, 0, 0, 0, 0], np.float32))
        assert info["acting"]["held"] == (not converged) and info["acting"]["proposed"] == "policy"
        if converged:
            assert reach.ee_pos[0] < before[0] - 0.0015 and reach.ee_pos[1] > before[1] + 0.004
            assert info["acting"]["source"] == "policy"
        else:
            np.testing.assert_array_equal(reach.q, q)
            np.testing.assert_array_equal(reach.ee_pos, before)
            assert info["acting"]["source"] == "held" and info["acting"]["held_by"] == "shield"
    finally:
        env.close()


def test_memory_steps_must_be_a_whole_number():
    with pytest.raises(ValueError, match="memory_steps must be >= 0"):
        SafetyLayer(memory_steps=-1)
    with pytest.raises(ValueError, match="whole number"):
        SafetyLayer(memory_steps=2.5)


def _box_behind(ee):  # its +x face 9 cm to the -x of the tool point
    return ObstacleSpec("box", (ee[0] - 0.14, ee[1], ee[2]), half_extents=(0.05, 0.15, 0.15))


def _push_into_a_box(safety: SafetyLayer | ActingConfig, steps: int = 60, **env_options):
    """The UR5 at exp1's start, a box face 9 cm to the -x of the tool point, the action pushing
    -x, acting through ``safety`` alone (or the layers of an ``ActingConfig``); the step count
    and the last step's info, with the start and, for all steps, the shielded terms,
    ``info["acting"]`` and the end-effector positions."""
    config = safety if isinstance(safety, ActingConfig) else layers(safety=safety)
    env = acting_around_the_tool([_box_behind], config, **env_options)
    shielded, acting, path = [], [], []
    try:
        _, start = env.reset(seed=0)
        for k in range(steps):
            _, _, terminated, _, info = env.step(np.array([-1, 0, 0, 0, 0, 0], np.float32))
            shielded.append(info["reward_terms"]["shielded"])
            acting.append(info["acting"])
            path.append(info["ee_position"])
            if terminated:
                break
        return k + 1, {**info, "start": start["ee_position"], "shielded": shielded, "steps_acting": acting,
                       "ee_path": path}
    finally:
        env.close()


def test_shield_keeps_the_tool_off_a_box_the_policy_drives_into():
    steps, info = _push_into_a_box(SafetyLayer())
    assert info["collision"] and steps < 60  # the push alone hits the box
    steps, info = _push_into_a_box(ACTING_SAFETY)
    assert steps == 60 and not info["collision"]


def test_slide_carries_the_held_tool_along_the_box_to_a_goal_beside_it():
    """The push is held at the box; the goal lies 10 cm to the side of the start. The shield
    alone holds the tool there; the slide carries it along the box to within 2 cm of the goal
    (the last of it is the push's, which draws the tool back to the box whenever it leaves)."""
    beside = np.array([0.0, 0.1, 0.0])
    steps, info = _push_into_a_box(SafetyLayer(workspace_guard=0.01, ray_shield=0.05), goal_offset=beside)
    assert steps == 60 and not info["collision"] and info["distance"] > 0.09
    assert {a["source"] for a in info["steps_acting"]} <= {"policy", "held"}
    steps, info = _push_into_a_box(SLIDING, goal_offset=beside)
    assert steps == 60 and not info["collision"] and info["distance"] < 0.02
    assert "slide" in {a["source"] for a in info["steps_acting"]}


def test_a_held_goal_step_moves_the_tool_along_the_box_and_never_into_it():
    """The goal lies straight behind the box, so the goal's own step is held as well as the
    push. The shield alone holds the tool still; with the slide it steps a full step along
    the box face every step and never touches the box. It goes back and forth about the
    goal's side position: the rule keeps no memory of which way it went."""
    still = _positions_pushing_into_a_box(SafetyLayer(workspace_guard=0.01, ray_shield=0.05))
    assert np.ptp(still[-20:], axis=0).max() < 1e-3
    moving = _positions_pushing_into_a_box(SLIDING)
    steps = np.linalg.norm(np.diff(moving[-20:], axis=0), axis=1)
    assert np.all(steps > 0.004)


def test_slide_steps_along_the_allowed_direction_nearest_the_goal_when_the_goal_step_is_held():
    """Under the ceiling, with a fan of near rays ahead and below and the goal beyond them
    (the traced UR5 timeouts): the goal's step projects to nothing, so the slide takes a
    step as long along the allowed direction at the smallest angle to it."""
    layer = SafetyLayer(workspace_guard=0.01, ray_shield=0.05, slide=SLIDE)
    fan = np.array([[0.3, 0.0, -0.95], [0.3, 0.3, -0.9], [0.3, -0.3, -0.9], [0.7, 0.1, -0.7]])
    fan /= np.linalg.norm(fan, axis=1, keepdims=True)
    at_ceiling, distances = np.array([0.0, 0.5, 0.4901]), np.full(4, 0.03)
    goal_step = np.array([0.0049, 0.0002, -0.001])
    push = np.array([0.004, 0.0, 0.003, 0.0, 0.0, 0.0])
    no_slide = SafetyLayer(workspace_guard=0.01, ray_shield=0.05)
    held = no_slide.filter(np.r_[goal_step, np.zeros(3)], at_ceiling, LOW, HIGH, distances, fan)
    assert np.linalg.norm(held[:3]) < 1e-9
    out = layer.filter(push, at_ceiling, LOW, HIGH, distances, fan, towards_goal=goal_step)[:3]
    rules = np.vstack([fan, Z])
    assert np.linalg.norm(out) == pytest.approx(np.linalg.norm(goal_step))
    assert np.all(rules @ out <= 1e-12)
    np.testing.assert_allclose(out, nearest_direction_in_cone(goal_step, rules) * np.linalg.norm(goal_step))


def _positions_pushing_into_a_box(safety: SafetyLayer, steps: int = 60) -> np.ndarray:
    env = acting_around_the_tool([_box_behind], layers(safety=safety))
    try:
        env.reset(seed=0)
        positions = []
        for _ in range(steps):
            _, _, terminated, _, info = env.step(np.array([-1, 0, 0, 0, 0, 0], np.float32))
            assert not terminated and not info["collision"]
            positions.append(info["ee_position"])
        return np.array(positions)
    finally:
        env.close()


def test_nearest_direction_in_cone_matches_a_search_over_the_sphere():
    """Against 200,000 directions spread over the sphere: the allowed one nearest the goal's
    is as near as any of them (to the sphere's spacing), and allowed itself."""
    n = 200_000
    k = np.arange(n) + 0.5
    polar, azimuth = np.arccos(1 - 2 * k / n), np.pi * (1 + 5 ** 0.5) * k
    sphere = np.stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), np.cos(polar)], axis=1)
    rng = np.random.default_rng(1)
    for count in (1, 2, 3, 4, 6):
        for _ in range(5):
            normals = rng.normal(size=(count, 3))
            normals /= np.linalg.norm(normals, axis=1, keepdims=True)
            goal = rng.normal(size=3)
            way = nearest_direction_in_cone(goal, normals, 1e-12)
            allowed = sphere[np.all(sphere @ normals.T <= 0.0, axis=1)]
            if way is None:
                assert len(allowed) == 0
                continue
            assert np.linalg.norm(way) == pytest.approx(1.0) and np.all(normals @ way <= 1e-9)
            best = float((allowed @ goal).max()) / np.linalg.norm(goal)
            assert way @ goal / np.linalg.norm(goal) == pytest.approx(best, abs=2e-2)
            assert way @ goal / np.linalg.norm(goal) >= best - 1e-3


def test_shielded_term_costs_each_held_step_and_nothing_before():
    """The tool starts 9 cm from the box; it runs free until a ray sees the box nearer than
    the 5 cm shield (the rays start around the flange, ahead of the tool point), and every
    step after is held whole: the term is the full weight and the tool does not move."""
    held = SafetyLayer(workspace_guard=0.01, ray_shield=0.05)  # no slide: every push is held
    steps, info = _push_into_a_box(held, rewards=RewardWeights(shielded=-0.1))
    shielded = np.array(info["shielded"])
    assert steps == 60 and not info["collision"]
    free = int(np.argmax(shielded < 0))
    assert 1 <= free < 8 and np.all(shielded[:free] == 0.0)  # 8 free steps would end 4.5 cm off
    assert shielded[free:] == pytest.approx(-0.1)
    assert info["ee_position"][0] == pytest.approx(info["start"][0] - free * 0.005, abs=5e-4)


def test_env_guard_holds_the_tool_inside_exp1():
    """-y leaves exp1's workspace (y >= 0.3) at step 21 from y = 0.4; guarded, the tool
    stops 1 cm inside and keeps moving along x."""
    env = ActingEnv(ReachEnv(robot="ur5", scenario="exp1"), layers(safety=SafetyLayer(workspace_guard=0.01)))
    reach = env.unwrapped
    try:
        env.reset(seed=0)
        x0 = reach.ee_pos[0]
        for _ in range(40):
            _, _reward, terminated, _truncated, info = env.step(np.array([0.3, -1, 0, 0, 0, 0], np.float32))
            assert not terminated and not info["out_of_bounds"]
            assert info["acting"]["source"] == "policy"  # reshaped, never replaced
        assert 0.31 - 0.005 <= reach.ee_pos[1] <= 0.31 + 1e-3
        assert reach.ee_pos[0] == pytest.approx(x0 + 40 * 0.3 * 0.005, abs=2e-3)
    finally:
        env.close()


def test_without_the_guard_the_same_push_leaves_exp1():
    """The guard's test above, with the guard switched off by name: the tool leaves the
    workspace and the episode ends."""
    config = layers(safety=SafetyLayer(workspace_guard=0.01)).without("workspace_guard")
    assert config.safety.workspace_guard == 0.0 and "workspace_guard" not in config.layers
    env = ActingEnv(ReachEnv(robot="ur5", scenario="exp1"), config)
    try:
        env.reset(seed=0)
        for _ in range(40):
            _, _, terminated, _, info = env.step(np.array([0.3, -1, 0, 0, 0, 0], np.float32))
            if terminated:
                break
        assert info["out_of_bounds"]
    finally:
        env.close()


def test_a_plate_in_front_of_the_tool_holds_the_push_and_the_slide_takes_over():
    """The box's face across the push, through the shield alone (the other layers off by
    name): once a ray sees it within the shield, the push is cut to nothing and the tool
    stays where it is, the policy's step reshaped, not replaced (IK's one iteration on the
    empty step may turn the joints by rounding, so ``held`` is not promised). With the slide
    the held push becomes a step along the face (``source`` slide), the arm never still."""
    alone = ActingConfig().without("final_approach", "detour", "slide", "arm_guard", "resample")
    assert alone.layers == ("ray_shield", "workspace_guard")
    steps, info = _push_into_a_box(alone)
    acting, path = info["steps_acting"], np.array(info["ee_path"])
    assert steps == 60 and not info["collision"]
    moved = np.linalg.norm(np.diff(np.vstack([info["start"], path]), axis=0), axis=1)
    first = int(np.argmax(moved < 1e-6))
    assert 1 <= first < 8 and np.all(moved[:first] > 0.004) and np.all(moved[first:] < 1e-6)
    assert all(a["source"] in ("policy", "held") and a["proposed"] == "policy" for a in acting)
    assert all(a["held_by"] == "shield" for a in acting if a["held"])  # the push cut to nothing
    steps, info = _push_into_a_box(SLIDING_STACK.without("final_approach", "detour", "arm_guard", "resample"))
    acting = info["steps_acting"]
    assert steps == 60 and not info["collision"]
    slid = [a for a in acting if a["source"] == "slide"]
    assert len(slid) > 40 and not any(a["held"] for a in slid)
    assert not any(a["held"] for a in acting)
