"""``ArmController``, the planner on a real arm: the same steps as ``ActingEnv`` on the same
readings, the arm's rule on capsules held to PyBullet's, no simulator or torch needed, and
clear errors for bad readings."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from importlib import resources

import numpy as np
import pytest

from rayreach.acting import ActingConfig, ActingEnv, ActingPolicy, ArmController
from rayreach.acting.arm_guard import CAPSULE_FILE, ChainCapsules
from rayreach.acting.mesh_capsules import PAD, ArmCapsules, capsule_table
from rayreach.env.reach import ReachEnv
from rayreach.learning.onnx_export import export_onnx
from rayreach.learning.policy import load_policy
from rayreach.planners.drl import shipped_model
from rayreach.robots.urdf import TOOL_LINK
from scenes import box_beside_the_forearm, elbow_step_towards, on_the_box, plate_over_the_tip, wall_before_the_goal


@pytest.mark.parametrize("robot, scenario", [("ur5", "exp1"), ("kr16", "exp4")])
def test_controller_commands_what_the_acting_env_does(robot, scenario):
    """Fed each step's joints and ray fractions from the simulation, the controller's target is
    the joints the simulated arm moves to, step for step (the arm's rule off: it measures
    capsules here and meshes there)."""
    config = ActingConfig().without("arm_guard")
    policy = load_policy(shipped_model(robot))
    env = ActingEnv(ReachEnv(robot=robot, scenario=scenario, observation=policy.observation), config)
    try:
        actor = ActingPolicy(policy, resample=config.resample)
        actor.reset(0)
        obs, info = env.reset(seed=0)
        reach = env.unwrapped
        world = reach.scenario
        controller = ArmController(policy, acting=config, base_position=world.base_position, base_rpy=world.base_rpy)
        controller.reset(reach.q, reach.goals[0], world.workspace_low, world.workspace_high)
        sources = set()
        for _ in range(400):
            step = controller.step(reach.q.copy(), reach._ray_fractions.copy())
            obs, _, terminated, truncated, info = env.step(actor.act(obs, info))
            np.testing.assert_allclose(step.q_target, reach.q, atol=1e-12)
            assert (step.source, step.held_by) == (info["acting"]["source"], info["acting"]["held_by"])
            sources.add(step.source)
            if terminated or truncated:
                break
        assert info["is_success"] and {"policy", "final_approach"} <= sources
        done = controller.step(reach.q.copy(), reach._ray_fractions.copy())
        assert done.reached and done.held and np.array_equal(done.q_target, reach.q)
    finally:
        env.close()


def test_shipped_capsules_are_a_fresh_fit():
    """The package's capsule file is what fitting the collision meshes gives now."""
    shipped = json.loads(resources.files("rayreach.models").joinpath(CAPSULE_FILE).read_text())
    fresh = capsule_table()
    assert shipped.keys() == fresh.keys() == {"ur5", "kr16", "ur10"}
    for robot, rows in fresh.items():
        assert [r["link"] for r in shipped[robot]] == [r["link"] for r in rows]
        for ours, theirs in zip(shipped[robot], rows):
            assert ours["frame"] == theirs["frame"]
            np.testing.assert_allclose(ours["ends"], theirs["ends"], atol=1e-6)
            assert ours["radius"] == pytest.approx(theirs["radius"], abs=1e-6)


@pytest.mark.parametrize("robot", ["ur5", "kr16", "ur10"])
def test_chain_capsules_sit_where_pybullet_puts_the_links_and_never_read_farther(robot, rigs):
    """Placed by the chain's kinematics, the capsules lie where PyBullet's link states put them;
    a point's distance to a capsule is at most PyBullet's distance to the mesh inside (less
    its padding), so the rule on capsules refuses whatever the rule on meshes refuses."""
    rig = rigs[robot]
    links = (*rig.spec.blind_links, TOOL_LINK)
    chain, mesh = ChainCapsules.shipped(rig.kin, links), ArmCapsules(rig.scene, links)
    rng = np.random.default_rng(4)
    nearer = 0
    for _ in range(20):
        q = np.asarray(rig.spec.home) + rng.uniform(-0.8, 0.8, 6)
        ends, mesh_ends = chain.pose(q), mesh.pose(q)
        np.testing.assert_allclose(ends[0], mesh_ends[0], atol=1e-6)
        np.testing.assert_allclose(ends[1], mesh_ends[1], atol=1e-6)
        k = rng.integers(len(links))
        points = (ends[0][k] + rng.uniform(0, 1) * (ends[1][k] - ends[0][k])
                  + rng.normal(0, 1, (40, 3)) * (chain.radii[k] + 0.02))
        for point in points:
            ours = chain.clearance(point[None], 0.05, ends)
            theirs = mesh.clearance(point[None], 0.05, mesh_ends)
            assert ours <= theirs + PAD
            nearer += ours < theirs - 0.005
    assert nearer > 0  # the capsules are the coarser measure: the comparison can tell them apart


def test_controller_needs_neither_pybullet_nor_torch(tmp_path):
    """On onnxruntime and numpy alone, the controller takes a UR5 from home to a goal 12 cm off
    in an empty cell (every ray reads 1), the arm following each target."""
    graph = export_onnx(shipped_model("ur5"), tmp_path / "ur5.onnx")
    code = f"""
import sys
for name in ("pybullet", "torch", "stable_baselines3"):
    sys.modules[name] = None  # any import of these now fails
import numpy as np
from rayreach.acting import ArmController
from rayreach.robots import get_robot
controller = ArmController({str(graph)!r})
q = np.array(get_robot("ur5").home)
tip = controller.kin.fk(q)[:3, 3]
controller.reset(q, tip + np.array([0.08, 0.05, -0.07]))
for n in range(600):
    step = controller.step(q, np.ones(129))
    if step.reached or step.outside:
        break
    q = step.q_target
print(step.reached, step.outside, n, round(step.distance, 4))
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    reached, outside, steps, distance = done.stdout.split()[-4:]
    assert (reached, outside) == ("True", "False") and float(distance) < 0.01 and int(steps) < 600


@pytest.fixture(scope="module")
def controller():
    made = ArmController("ur5")
    made.reset(made.spec.home, [0.0, 0.5, 0.3])
    return made


def test_controller_takes_metres_as_well_as_fractions(controller):
    home = np.asarray(controller.spec.home)
    controller.reset(home, [0.0, 0.5, 0.3])
    in_fractions = controller.step(home, np.full(129, 0.5))
    controller.reset(home, [0.0, 0.5, 0.3])
    in_metres = controller.step(home, np.full(129, 0.5 * controller.ray_range), unit="m")
    np.testing.assert_array_equal(in_fractions.q_target, in_metres.q_target)
    assert controller._fractions(np.full(129, 7.0), "m", 1.0).tolist() == [1.0] * 129  # beyond the range: nothing seen


@pytest.mark.parametrize("readings, unit, message", [
    (np.ones(128), "fraction", "readings must hold the 129 rays"),
    (np.full(129, 0.3) + np.eye(129)[5], "fraction", "rays [5] exceed 1 (metres? pass unit='m')"),
    (np.r_[np.ones(128), np.nan], "fraction", "rays [128] are not"),
    (-np.ones(129), "m", "must be finite and >= 0"),
    (np.ones(129), "feet", "unknown unit 'feet'; valid: fraction, m"),
])
def test_controller_refuses_bad_readings_saying_what_is_valid(controller, readings, unit, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        controller.step(controller.spec.home, readings, unit=unit)


def test_controller_refuses_bad_joints_goals_and_order():
    made = ArmController("ur5")
    with pytest.raises(RuntimeError, match=r"call reset\(q, goal\) before step\(\)"):
        made.step(made.spec.home, np.ones(129))
    q = np.array(made.spec.home)
    q[2] = 4.0
    with pytest.raises(ValueError, match=r"elbow_joint=4.000 not in \[-3.142, 3.142\]"):
        made.reset(q, [0.0, 0.5, 0.3])
    with pytest.raises(ValueError, match="goal must be 3 finite numbers"):
        made.reset(made.spec.home, [0.0, 0.5])
    with pytest.raises(ValueError, match="workspace_low .* must lie below workspace_high"):
        made.reset(made.spec.home, [0.0, 0.5, 0.3], [0, 0, 0], [1, -1, 1])
    with pytest.raises(ValueError, match="trained for 'ur5', not 'kr16'"):
        ArmController("ur5", robot="kr16")


def _follow_beside_the_env(tmp_path, observation, scenario, n_readings: int, refused: str, readings, steps: int):
    """A tiny policy reading ``observation`` acts in ``scenario`` (arm guard off) and a
    controller beside it is fed ``readings(reach, k)`` (readings, unit) at each step ``k``:
    its observation and joint target must be the env's. The 129 alone are refused with
    ``refused``."""
    from rayreach.learning.train import TrainConfig, train

    config = TrainConfig(robot="ur5", timesteps=64, envs=1, n_steps=64, batch_size=64, n_epochs=1,
                         observation=observation)
    policy = load_policy(train(config, tmp_path))
    acting = ActingConfig().without("arm_guard")
    env = ActingEnv(ReachEnv(scenario=scenario, observation=policy.observation), acting)
    try:
        actor = ActingPolicy(policy, resample=acting.resample)
        actor.reset(0)
        obs, info = env.reset(seed=0)
        reach = env.unwrapped
        controller = ArmController(policy, acting=acting, base_position=reach.scenario.base_position,
                                   base_rpy=reach.scenario.base_rpy)
        assert controller.n_readings == n_readings
        controller.reset(reach.q, reach.goals[0], reach.scenario.workspace_low, reach.scenario.workspace_high)
        with pytest.raises(ValueError, match=re.escape(refused)):
            controller.step(reach.q.copy(), reach._ray_fractions.copy())
        for k in range(steps):
            step = controller.step(reach.q.copy(), *readings(reach, controller, k))
            np.testing.assert_allclose(controller.observer.obs[0], obs, atol=1e-6)
            obs, _, terminated, truncated, info = env.step(actor.act(obs, info))
            np.testing.assert_allclose(step.q_target, reach.q, atol=1e-12)
            if terminated or truncated:
                break
    finally:
        env.close()


@pytest.mark.parametrize("sightings", [0, 3])
def test_a_policy_with_tip_back_rays_reads_them_after_the_129(tmp_path, sightings):
    """A policy observing the tip-back rays (and remembering sightings over them and the
    129): fed the 129 and then the 24 from the simulation, the controller builds the
    observation the env built and commands the same joints; the 129 alone are refused with
    what it takes."""
    from rayreach.env.observation import ObservationConfig

    def readings(reach, controller, k):
        assert (reach._extra_fractions < 1).sum() >= 4 or k  # the plate is in their sight
        return np.r_[reach._ray_fractions, reach._extra_fractions], "fraction"

    _follow_beside_the_env(tmp_path, ObservationConfig(motion=True, tip_back=True, sightings=sightings),
                           plate_over_the_tip(back=0.05, centre_out=0.1, half=0.07), 153,
                           "readings must hold the 129 rays, then the 24 tip-back rays", readings, 40)


def test_a_policy_with_arm_rays_reads_them_after_the_129(tmp_path):
    """A policy observing the rays round its upper arm and forearm: fed the 129 and then the 64
    from the simulation, the controller (whose mounts sit on chain frames 2 and 3, not the
    flange) builds the observation the env built and commands the same joints."""
    from rayreach.env.observation import ObservationConfig

    def readings(reach, controller, k):
        assert (reach._extra_fractions < 1).sum() >= 2 or k  # the box is in their sight
        return np.r_[reach._ray_fractions, reach._extra_fractions], "fraction"

    _follow_beside_the_env(tmp_path, ObservationConfig(motion=True, arm_rays=True, sightings=2),
                           box_beside_the_forearm(0.12), 193,
                           "readings must hold the 129 rays, then the 64 arm rays", readings, 20)


def test_a_policy_with_goal_rays_reads_them_last_in_fractions_or_metres(tmp_path):
    """A policy observing the rays aimed at the goal: the controller says where to cast them
    (as the env casts them) and, fed their readings after the 129, as fractions of their
    length or in metres, builds the observation the env built."""
    from rayreach.env.observation import ObservationConfig
    from rayreach.sim.goal_rays import goal_rays

    seen = []

    def readings(reach, controller, k):
        origins, directions, length = controller.goal_rays(reach.q)
        expected = goal_rays(reach.ee_pos[None], reach.ee_rot[None, :, 2], reach.goals[0][None], 0.13)
        np.testing.assert_allclose(origins, expected[0][0], atol=1e-9)
        np.testing.assert_allclose(directions, expected[1][0], atol=1e-9)
        clear = reach.caster.cast(origins, directions, length)
        seen.append((clear < 1).any())
        if k % 2:
            return np.r_[reach._ray_fractions, clear], "fraction"
        return np.r_[reach._ray_fractions * 0.4, np.where(clear < 1, clear * length, 5.0)], "m"

    _follow_beside_the_env(tmp_path, ObservationConfig(motion=True, goal_sight=True), wall_before_the_goal(0.1, 0.2, 0.1),
                           132, "readings must hold the 129 rays, then the 3 goal rays", readings, 30)
    assert any(seen)  # the wall stood between the tool and the goal


@pytest.mark.parametrize("policy_reads_them", [False, True])
def test_the_arm_rules_arm_rays_on_a_real_arm_keep_the_forearm_off_a_box(tmp_path, policy_reads_them):
    """With ``SafetyLayer.arm_rays`` the controller reads the 64 rays round the upper arm and
    the forearm (after the policy's own rays, or among them where the policy observes them):
    fed what PyBullet casts beside a box 6 cm off the forearm, no tool ray seeing it, the box's
    face enters the seen points and the rule on the shipped capsules (upper arm included)
    refuses an elbow step towards it and takes one away."""
    from dataclasses import replace

    from rayreach.acting.layers import ArmRule
    from rayreach.env.observation import ObservationConfig
    from rayreach.learning.train import TrainConfig, train
    from rayreach.sim.sensors import RayModel, arm_layout

    policy = "ur5"
    if policy_reads_them:
        config = TrainConfig(robot="ur5", timesteps=64, envs=1, n_steps=64, batch_size=64, n_epochs=1,
                             observation=ObservationConfig(motion=True, arm_rays=True))
        policy = load_policy(train(config, tmp_path))
    scenario = box_beside_the_forearm(0.06, along=0.8, side=-1.0)
    acting = ActingConfig()
    acting = replace(acting, safety=replace(acting.safety, arm_clearance=0.01, arm_rays=True))
    reach = ReachEnv(scenario=scenario)
    try:
        reach.reset(seed=0)
        q = reach.q.copy()
        spec = reach.spec_robot
        origins, directions = RayModel(spec, reach.config.ray_range, arm_layout(spec)).world_rays(reach.frames)
        arm = reach.caster.cast(origins, directions, reach.config.ray_range)
        assert (arm < 1).sum() >= 2  # the rings facing the box
        controller = ArmController(policy, acting=acting, base_position=scenario.base_position,
                                   base_rpy=scenario.base_rpy)
        assert controller.n_readings == 129 + 64
        controller.reset(q, reach.goals[0], scenario.workspace_low, scenario.workspace_high)
        with pytest.raises(ValueError, match=re.escape("the 129 rays, then the 64 arm rays")):
            controller.step(q, reach._ray_fractions.copy())
        controller.step(q, np.r_[reach._ray_fractions, arm])
    finally:
        reach.close()
    rule = next(c for c in controller.components if isinstance(c, ArmRule))
    assert "upper_arm_link" in rule.capsules.names
    points = controller._episode.memory.seen_points(100)
    box = scenario.obstacles[0]
    assert on_the_box(points, box).sum() >= 2
    toward = elbow_step_towards(controller.kin, q, np.asarray(box.position))
    assert rule.guard.allows(q, q - toward, points) and not rule.guard.allows(q, q + toward, points)
