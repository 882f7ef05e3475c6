"""The arm's rule: capsules against plain geometry and PyBullet's own distances, the seen
points it reads from the ray memory, then acting through ``ActingEnv``."""

from __future__ import annotations

import dataclasses

import numpy as np
import pybullet as p
import pytest

from exp1_scenes import layers
from rayreach.acting import ActingEnv
from rayreach.acting.mesh_capsules import PAD, PROBE, VOXEL, ArmCapsules, first_per_cell
from rayreach.sim.geometry import capsule_around
from rayreach.acting.controller import SHORTER
from rayreach.acting.layers import ArmRule
from rayreach.acting.memory import RayMemory
from rayreach.acting.shield import SafetyLayer
from rayreach.env.perception import Perception
from rayreach.env.reach import ReachEnv
from rayreach.robots import get_robot
from rayreach.robots.urdf import TCP_LINK, TOOL_LINK
from rayreach.sim.geometry import distances_to_segment
from rayreach.sim.scene import Scene


def test_a_fitted_capsule_holds_a_cylinders_points_and_no_more_than_needed():
    angle = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    ring = np.stack([0.05 * np.cos(angle), 0.05 * np.sin(angle), np.zeros_like(angle)], axis=1)
    cylinder = np.concatenate([ring, ring + [0.0, 0.0, 0.3]])
    a, b, radius = capsule_around(cylinder)
    assert radius == pytest.approx(0.05, abs=1e-9)
    assert sorted([a[2], b[2]]) == pytest.approx([0.0, 0.3])


@pytest.mark.parametrize("robot", ["ur5", "kr16"])
def test_capsules_are_never_nearer_than_pybullet_says_the_link_is(robot):
    """PyBullet's distance from each link's collision mesh to a point is the reference: the
    capsules may only report less (they wrap the mesh), and a point inside a link must be
    inside its capsule."""
    spec = get_robot(robot)
    scene = Scene(spec)
    try:
        meshed = tuple(name for name, index in scene.link_indices.items() if name != TCP_LINK
                       and p.getMeshData(scene.robot, index, physicsClientId=scene.client)[0] >= 4)
        assert set(spec.blind_links) | {TOOL_LINK} < set(meshed) and len(meshed) >= 7
        capsules = ArmCapsules(scene, meshed)
        probe = p.createCollisionShape(p.GEOM_SPHERE, radius=1e-4, physicsClientId=scene.client)
        rng = np.random.default_rng(0)
        for _ in range(3):
            scene.set_joints(np.asarray(spec.home) + rng.uniform(-0.5, 0.5, len(spec.home)))
            a, b = capsules.world()
            for k, link in enumerate(capsules.links):
                centre = (a[k] + b[k]) / 2
                points = centre + rng.uniform(-0.3, 0.3, (40, 3))
                for point in points:
                    close = p.getClosestPoints(scene.robot, -1, 1.0, linkIndexA=link, collisionShapeB=probe,
                                               collisionShapePositionB=point.tolist(), physicsClientId=scene.client)
                    truth = min(c[8] for c in close) if close else 1.0
                    ours = float(distances_to_segment(point[None], a[k], b[k] - a[k])[0] - capsules.radii[k])
                    assert ours <= truth + PAD  # PyBullet pads its meshes by about a millimetre
                    assert truth >= 0 or ours < 0
    finally:
        scene.close()


@pytest.mark.parametrize("robot", ["ur5", "kr16"])
def test_clearance_misses_no_point_pybullet_finds_near_a_blind_link(robot):
    """The capsules only pick which points to measure: the result is PyBullet's least
    distance over every point and link, capped at ``within``."""
    spec = get_robot(robot)
    scene = Scene(spec)
    try:
        links = ArmCapsules(scene, (*spec.blind_links, TOOL_LINK))
        probe = p.createCollisionShape(p.GEOM_SPHERE, radius=PROBE, physicsClientId=scene.client)
        rng = np.random.default_rng(1)
        scene.set_joints(np.asarray(spec.home))
        a, b = links.world()
        for within in (0.01, 0.03, 0.1):
            points = (a[0] + b[-1]) / 2 + rng.uniform(-0.25, 0.25, (150, 3))
            truth = within
            for link in links.links:
                for point in points:
                    close = p.getClosestPoints(scene.robot, -1, within, linkIndexA=link, collisionShapeB=probe,
                                               collisionShapePositionB=point.tolist(), physicsClientId=scene.client)
                    truth = min([truth, *(c[8] for c in close)])
            assert links.clearance(points, within) == pytest.approx(truth, abs=1e-12)
        assert truth < 0.1  # some points were near enough to matter
    finally:
        scene.close()


RANGE = 0.4


def _seeing(points: np.ndarray, base: Perception | None = None) -> Perception:
    """A perception whose rays hit ``points`` (world, (n, 3)), each from 1 cm before it, plus one
    ray that sees nothing; or ``base`` with those rays added to its own."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    direction = np.array([0.0, 0.0, -1.0])
    origins = np.vstack([points - 0.01 * direction, np.zeros((1, 3))])
    directions = np.tile(direction, (len(origins), 1))
    lengths = np.r_[np.full(len(points), 0.01), RANGE]
    if base is None:
        return Perception(step=0, q=np.zeros(6), ee_position=np.zeros(3), ee_rotation=np.eye(3), goal=np.zeros(3),
                          origins=origins, directions=directions, lengths=lengths, fractions=lengths / RANGE,
                          workspace_low=-np.ones(3), workspace_high=np.ones(3))
    return dataclasses.replace(base, origins=np.vstack([base.origins, origins]),
                               directions=np.vstack([base.directions, directions]),
                               lengths=np.r_[base.lengths, lengths], fractions=np.r_[base.fractions, lengths / RANGE])


def test_seen_points_forget_old_steps():
    memory = RayMemory()
    assert memory.seen_points(2).shape == (0, 3)
    memory.add(_seeing([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0]]), moved=True)
    memory.add(_seeing([[1.0, 0.0, 0.0]]), moved=True)
    np.testing.assert_allclose(memory.seen_points(2), [[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [1.0, 0.0, 0.0]])
    memory.add(_seeing(np.zeros((0, 3))), moved=True)
    memory.add(_seeing([[2.0, 0.0, 0.0]]), moved=True)
    np.testing.assert_allclose(memory.seen_points(2), [[2.0, 0.0, 0.0]])
    assert memory.seen_points(0).shape == (0, 3)


def test_seen_points_age_only_as_the_arm_moves():
    """Scans after a held step add nothing and do not push the older ones out."""
    memory = RayMemory()
    memory.add(_seeing([[0.0, 0.0, 0.0]]), moved=True)
    memory.add(_seeing([[1.0, 0.0, 0.0]]), moved=False)
    memory.add(_seeing([[2.0, 0.0, 0.0]]), moved=False)
    np.testing.assert_allclose(memory.seen_points(1), [[0.0, 0.0, 0.0]])
    memory.add(_seeing([[3.0, 0.0, 0.0]]), moved=True)
    np.testing.assert_allclose(memory.seen_points(1), [[3.0, 0.0, 0.0]])
    np.testing.assert_allclose(memory.seen_points(5), [[0.0, 0.0, 0.0], [3.0, 0.0, 0.0]])


def test_points_in_one_voxel_are_measured_once_the_first_kept():
    points = np.array([[VOXEL / 4, 0.0, 0.0], [0.0, 0.0, 3 * VOXEL], [0.0, 0.0, 0.0], [-VOXEL / 4, 0.0, 0.0]])
    assert first_per_cell(points).tolist() == [0, 1, 3]


def _arm_rule(env: ActingEnv) -> ArmRule:
    """The arm's rule among ``env``'s components."""
    (rule,) = [c for c in env.components if isinstance(c, ArmRule)]
    return rule


def _walk_beside(point_side: float, steps: int = 1, memory: int = 5, gap: float = 0.015, link_name: str = "link_5",
                 guard_tool: bool = False, arm_clearance: float = 0.02, tool_clearance: float | None = None,
                 without: tuple[str, ...] = ()) -> tuple[float, list[dict]]:
    """``steps`` +x steps of the KR16 in exp4, acting through the arm's rule alone (and not
    even that with ``without=("arm_guard",)``), with one seen point placed ``gap`` off the
    surface of ``link_name`` (default: the wrist) on the side ``point_side`` (+1: where the
    steps go), the rule's clearance 2 cm unless given. The point enters the ray memory as one
    more ray of the start's scan. Returns how far the tool moved and each step's
    ``info["acting"]``."""
    layer = SafetyLayer(arm_clearance=arm_clearance, arm_memory_steps=memory, guard_tool=guard_tool,
                        tool_clearance=tool_clearance)
    env = ActingEnv(ReachEnv(robot="kr16", scenario="exp4"), layers(safety=layer).without(*without))
    reach = env.unwrapped
    try:
        env.reset(seed=0)
        scene, link = reach.scene, reach.scene.link_indices[link_name]
        capsules = ArmCapsules(scene, (*reach.spec_robot.blind_links, TOOL_LINK))
        wrist = capsules.links.index(link)
        a, b = capsules.world()
        outward = point_side * np.array([1.0, 0.0, 0.0])
        far = (a[wrist] + b[wrist]) / 2 + 0.5 * outward
        probe = p.createCollisionShape(p.GEOM_SPHERE, radius=1e-4, physicsClientId=scene.client)
        close = p.getClosestPoints(scene.robot, -1, 1.0, linkIndexA=link, collisionShapeB=probe,
                                   collisionShapePositionB=far.tolist(), physicsClientId=scene.client)
        surface = np.asarray(min(close, key=lambda c: c[8])[5])
        point = surface + gap * outward
        env.memory.add(_seeing(point[None], base=env.memory.now), moved=True)
        assert any(np.allclose(seen, point) for seen in env.memory.seen_points(memory))
        before = reach.ee_pos.copy()
        acting = []
        for _ in range(steps):
            _, _, _, _, info = env.step(np.array([1.0, 0, 0, 0, 0, 0], np.float32))
            acting.append(info["acting"])
        return float(np.linalg.norm(info["ee_position"] - before)), acting
    finally:
        env.close()


def _step_beside(point_side: float, **options) -> float:
    """How far the tool moved in ``_walk_beside``."""
    return _walk_beside(point_side, **options)[0]


def test_a_step_that_sweeps_the_wrist_towards_a_seen_point_is_refused_and_one_away_is_taken():
    assert _step_beside(+1.0) == 0.0
    moved = _step_beside(-1.0)
    assert moved == pytest.approx(0.005, abs=5e-4)


def test_a_refused_step_is_taken_shorter_where_that_keeps_the_clearance():
    """2.3 cm off the wrist, a full step would bring it within 2 cm; a share of it does not.
    A deterministic policy would otherwise repeat the refused step until its budget ran out."""
    moved, acting = _walk_beside(+1.0, gap=0.023)
    assert 0.005 * min(SHORTER) - 5e-4 < moved < 0.005 * max(SHORTER) + 5e-4
    assert acting == [{"source": "policy", "proposed": "policy", "held": False, "held_by": ""}]
    assert _step_beside(+1.0, gap=0.035) == pytest.approx(0.005, abs=5e-4)  # far enough: the whole step


def test_unknown_or_meshless_links_are_refused_by_name():
    scene = Scene(get_robot("ur5"))
    try:
        with pytest.raises(ValueError, match="has no links \\['elbow'\\]; it has .*forearm_link"):
            ArmCapsules(scene, ("elbow",))
        with pytest.raises(ValueError, match="no collision mesh"):
            ArmCapsules(scene, (TCP_LINK,))
    finally:
        scene.close()


def test_the_tool_is_held_off_a_seen_point_only_where_the_rule_watches_it():
    """The KR16's tool is blind between its rays: with ``guard_tool`` a step that sweeps its
    side towards a point seen 1.5 cm off it is refused; without, the step is taken."""
    assert _step_beside(+1.0, link_name=TOOL_LINK, guard_tool=True) == 0.0
    assert _step_beside(+1.0, link_name=TOOL_LINK) == pytest.approx(0.005, abs=5e-4)
    assert _step_beside(-1.0, link_name=TOOL_LINK, guard_tool=True) == pytest.approx(0.005, abs=5e-4)


def test_the_tool_and_the_arm_are_each_held_to_their_own_clearance():
    """A point 1.8 cm off the tool holds it at a 2 cm tool clearance and not at 1 cm (a 5 mm
    step leaves 1.3 cm), whatever the arm's; a point 1.8 cm off the wrist holds it at the
    arm's 2 cm, whatever the tool's."""
    tool = dict(link_name=TOOL_LINK, guard_tool=True, gap=0.018)
    assert _step_beside(+1.0, arm_clearance=0.01, tool_clearance=0.02, **tool) == 0.0
    assert _step_beside(+1.0, arm_clearance=0.02, tool_clearance=0.01, **tool) == pytest.approx(0.005, abs=5e-4)
    assert _step_beside(+1.0, arm_clearance=0.02, tool_clearance=0.01, guard_tool=True, gap=0.018) == 0.0
    assert _step_beside(+1.0, arm_clearance=0.01, tool_clearance=0.02, guard_tool=True,
                        gap=0.018) == pytest.approx(0.005, abs=5e-4)


def test_the_final_approachs_step_leaves_the_tool_out_of_the_rule():
    """``tool=False`` (the final approach's steps, whose straight path was tested against
    every hit already) measures the arm alone: a point beside the tool holds the step only
    when the tool is watched."""
    env = ActingEnv(ReachEnv(robot="kr16", scenario="exp4"),
                    layers(safety=SafetyLayer(arm_clearance=0.02, guard_tool=True)))
    reach = env.unwrapped
    try:
        env.reset(seed=0)
        guard, tool = _arm_rule(env).guard, reach.scene.link_indices[TOOL_LINK]
        a, b = guard.links.world()
        k = guard.links.links.index(tool)
        axis = (b[k] - a[k]) / np.linalg.norm(b[k] - a[k])
        side = np.cross(axis, [0.0, 0.0, 1.0])
        side /= np.linalg.norm(side)
        points = np.vstack([env.memory.seen_points(100), (a[k] + b[k]) / 2 + (guard.links.radii[k] + 0.015) * side])
        ik = reach.solve(np.r_[0.005 * side, 0.0, 0.0, 0.0])
        assert ik.converged
        assert guard.allows(reach.q, ik.q, env.memory.seen_points(100))  # what the rays saw alone: no hold
        assert not guard.allows(reach.q, ik.q, points)
        assert guard.allows(reach.q, ik.q, points, tool=False)
    finally:
        env.close()


def test_a_held_arm_does_not_forget_what_holds_it():
    """With a memory of one step, the point would be gone after the first held step if held
    steps counted; they do not, so the arm stays held, and each step says so."""
    moved, acting = _walk_beside(+1.0, steps=5, memory=1)
    assert moved == 0.0
    assert acting == [{"source": "held", "proposed": "policy", "held": True, "held_by": "arm_guard"}] * 5


def test_the_arm_rule_refuses_and_reports_the_arm_held_where_it_is_on():
    """A seen point 1.5 cm off the wrist, the push sweeping the wrist towards it: the arm's
    rule refuses the step and every shorter share, the arm holds still and ``info`` says
    so; the same scene with the rule switched off by name takes the whole step."""
    moved, acting = _walk_beside(+1.0)
    assert moved == 0.0 and acting == [{"source": "held", "proposed": "policy", "held": True, "held_by": "arm_guard"}]
    moved, acting = _walk_beside(+1.0, without=("arm_guard",))
    assert moved == pytest.approx(0.005, abs=5e-4)
    assert acting == [{"source": "policy", "proposed": "policy", "held": False, "held_by": ""}]


def test_arm_rule_settings_are_checked():
    with pytest.raises(ValueError, match="arm_clearance must be >= 0"):
        SafetyLayer(arm_clearance=-0.01)
    with pytest.raises(ValueError, match="arm_memory_steps counts steps"):
        SafetyLayer(arm_memory_steps=2.5)
    with pytest.raises(ValueError, match="guard_tool is True or False, got 'yes'"):
        SafetyLayer(guard_tool="yes")
    with pytest.raises(ValueError, match="tool_clearance must be > 0"):
        SafetyLayer(tool_clearance=0.0)


@pytest.mark.parametrize("arm_rays", [False, True])
def test_with_the_arm_rays_the_rule_keeps_the_forearm_off_a_box_no_tool_ray_sees(arm_rays):
    """A box 6 cm from the UR5 forearm's axis near the elbow, where none of the 129 rays look:
    with ``SafetyLayer.arm_rays`` its face enters the seen points and an elbow step that
    swings the forearm towards it is refused, one away is taken; without, the rule knows
    nothing of it. The upper arm is guarded only with the arm rays."""
    from scenes import box_beside_the_forearm, elbow_step_towards, on_the_box

    box_face_gap = 0.06
    scenario = box_beside_the_forearm(box_face_gap, along=0.8, side=-1.0)
    layer = SafetyLayer(arm_clearance=0.01, arm_rays=arm_rays)
    env = ActingEnv(ReachEnv(scenario=scenario), layers(safety=layer))
    reach = env.unwrapped
    try:
        env.reset(seed=0)
        rule = next(c for c in env.components if isinstance(c, ArmRule))
        assert ("upper_arm_link" in rule.capsules.names) == arm_rays
        points = env.memory.seen_points(100)
        box = scenario.obstacles[0]
        on_box = on_the_box(points, box)
        assert on_box.sum() >= 2 if arm_rays else on_box.sum() == 0  # the rings that face it
        q = reach.q.copy()
        toward = elbow_step_towards(reach.kin, q, np.asarray(box.position))
        assert rule.guard.allows(q, q - toward, points)
        assert rule.guard.allows(q, q + toward, points) != arm_rays
    finally:
        env.close()
