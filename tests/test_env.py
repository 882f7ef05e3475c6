"""The Gymnasium environment: API conformance, observation, actions, rewards and episode ends,
determinism, isolation between environments, rendering."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np
import pybullet as p
import pytest

import rayreach
from exp1_scenes import exp1_around_the_tool
from rayreach.env.reach import OBS_SIZE, ReachEnv
from rayreach.scenarios.schema import ObstacleSpec
from rayreach.sim.sensors import N_RAYS
from rayreach.sim.transforms import matrix_to_rotvec, matrix_to_rpy, rotvec_to_matrix

UR5_ID, KR16_ID = "rayreach/Reach-UR5-v0", "rayreach/Reach-KR16-v0"


def rollout(env, seed, actions, reset_at=()):
    """Observations of a rollout; resets (without a seed) after an episode ends or at the
    listed steps."""
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for k, a in enumerate(actions):
        if k in reset_at:
            obs, _ = env.reset()
            out.append(obs)
        obs, _reward, terminated, truncated, _ = env.step(a)
        out.append(obs)
        if terminated or truncated:
            obs, _ = env.reset()
            out.append(obs)
    return out


def random_actions(n, seed=0, scale=1.0):
    return list(np.random.default_rng(seed).uniform(-scale, scale, (n, 6)).astype(np.float32))


# ---------------------------------------------------------------------- registration, checkers
def test_env_ids_registered():
    assert UR5_ID in rayreach.ENV_IDS and KR16_ID in rayreach.ENV_IDS
    for env_id in (UR5_ID, KR16_ID):
        env = gym.make(env_id)
        try:
            assert isinstance(env.unwrapped, ReachEnv)
            assert env.unwrapped.spec_robot.name == env_id.split("-")[1].lower()
        finally:
            env.close()


@pytest.mark.parametrize(
    "env_id, scenario", [(UR5_ID, "random"), (UR5_ID, "exp1"), (KR16_ID, "random"), (KR16_ID, "exp4")]
)
def test_gymnasium_and_sb3_env_checkers(env_id, scenario):
    from gymnasium.utils.env_checker import check_env as gym_check
    from stable_baselines3.common.env_checker import check_env as sb3_check

    env = gym.make(env_id, scenario=scenario)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # the unbounded robot part of the observation
            gym_check(env.unwrapped, skip_render_check=True)
            sb3_check(env.unwrapped, warn=False)
    finally:
        env.close()


# ---------------------------------------------------------------------- observation
@pytest.fixture(scope="module")
def exp1_env():
    env = gym.make(UR5_ID, scenario="exp1")
    yield env
    env.close()


def test_observation_layout_at_reset(exp1_env):
    obs, info = exp1_env.reset(seed=0)
    env = exp1_env.unwrapped
    assert obs.shape == (OBS_SIZE,) == (142,) and obs.dtype == np.float32
    assert exp1_env.observation_space.contains(obs)
    np.testing.assert_allclose(obs[0:6], env.q, atol=1e-6)
    ee = env.kin.fk(env.q)[:3, 3]
    goal = np.asarray(env.scenario.goals[0])
    np.testing.assert_allclose(obs[6:9], goal - ee, atol=1e-6)
    np.testing.assert_allclose(ee, (0.15, 0.4, 0.3), atol=1e-4)  # exp1's start pose
    np.testing.assert_allclose(obs[9:12], np.zeros(3), atol=1e-12)
    assert obs[12] == pytest.approx(np.linalg.norm(goal - ee), abs=1e-6)
    assert info["distance"] == pytest.approx(obs[12], abs=1e-6)
    rays = obs[13:]
    assert len(rays) == N_RAYS and np.all((rays >= 0) & (rays <= 1))
    # the plate 15 cm away along -x is seen by some rays
    assert np.any(rays < 1)
    origins, dirs = env.rays.world_rays(env.kin.frames(env.q))
    np.testing.assert_allclose(rays, env.scene.caster("numpy").cast(origins, dirs, 0.4), atol=1e-6)


def test_observation_tracks_the_state_while_stepping(exp1_env):
    exp1_env.reset(seed=1)
    env = exp1_env.unwrapped
    r0 = env.kin.fk(env.q)[:3, :3]
    goal = np.asarray(env.scenario.goals[0])
    for a in random_actions(40, seed=2, scale=0.5):
        obs, _, terminated, truncated, info = exp1_env.step(a)
        tip = env.kin.fk(env.q)
        np.testing.assert_allclose(obs[0:6], env.q, atol=1e-6)
        np.testing.assert_allclose(obs[6:9], goal - tip[:3, 3], atol=1e-6)
        assert obs[12] == pytest.approx(np.linalg.norm(goal - tip[:3, 3]), abs=1e-6)
        np.testing.assert_allclose(obs[9:12], matrix_to_rpy(r0.T @ tip[:3, :3]), atol=1e-6)
        np.testing.assert_allclose(info["ee_position"], tip[:3, 3], atol=1e-12)
        assert np.all((obs[13:] >= 0) & (obs[13:] <= 1))
        assert not (terminated or truncated)


def test_orientation_observation_is_continuous_for_a_downward_tool():
    """UR5 random worlds start with the tool pointing straight down, where raw Euler angles
    sit on the +-pi seam; the relative orientation must stay small and continuous."""
    env = ReachEnv(robot="ur5")
    try:
        env.set_n_obstacles(0)
        obs, _ = env.reset(seed=3)
        tool_z = env.kin.fk(env.q)[:3, 2]
        np.testing.assert_allclose(tool_z, [0, 0, -1], atol=1e-3)
        raw = [matrix_to_rpy(env.kin.fk(env.q)[:3, :3])]
        rng = np.random.default_rng(4)
        orientations = [obs[9:12].copy()]
        for _ in range(200):
            action = np.concatenate((np.zeros(3), rng.uniform(-1, 1, 3))).astype(np.float32)
            obs, _, terminated, truncated, _ = env.step(action)
            assert not (terminated or truncated)
            orientations.append(obs[9:12].copy())
            raw.append(matrix_to_rpy(env.kin.fk(env.q)[:3, :3]))
        o = np.array(orientations)
        assert np.abs(np.diff(o, axis=0)).max() < 0.05
        assert np.abs(o).max() < 0.5
        assert np.abs(o).max() > 0.01  # it did rotate
        # raw Euler angles of the same motion do jump across the seam: the test can fail
        assert np.abs(np.diff(np.array(raw), axis=0)).max() > 3.0
    finally:
        env.close()


# ---------------------------------------------------------------------- actions
def test_translation_action_moves_5_mm(exp1_env):
    for axis, sign in [(0, 1.0), (1, 1.0), (2, 1.0), (2, -1.0)]:
        exp1_env.reset(seed=0)
        env = exp1_env.unwrapped
        before = env.kin.fk(env.q)
        action = np.zeros(6, dtype=np.float32)
        action[axis] = sign
        exp1_env.step(action)
        after = env.kin.fk(env.q)
        expected = np.zeros(3)
        expected[axis] = 0.005 * sign
        np.testing.assert_allclose(after[:3, 3] - before[:3, 3], expected, atol=1e-4)
        assert np.linalg.norm(matrix_to_rotvec(after[:3, :3] @ before[:3, :3].T)) < 1e-4
    # half an action moves half as far; beyond 1 it is clipped
    for value, distance in [(0.5, 0.0025), (3.0, 0.005)]:
        exp1_env.reset(seed=0)
        before = env.kin.fk(env.q)[:3, 3]
        exp1_env.step(np.array([value, 0, 0, 0, 0, 0], dtype=np.float32))
        np.testing.assert_allclose(env.kin.fk(env.q)[:3, 3] - before, [distance, 0, 0], atol=1e-4)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_rotation_action_turns_5_mrad_about_a_world_axis(exp1_env, axis):
    exp1_env.reset(seed=0)
    env = exp1_env.unwrapped
    before = env.kin.fk(env.q)
    action = np.zeros(6, dtype=np.float32)
    action[3 + axis] = 1.0
    exp1_env.step(action)
    after = env.kin.fk(env.q)
    expected = np.zeros(3)
    expected[axis] = 0.005
    np.testing.assert_allclose(matrix_to_rotvec(after[:3, :3] @ before[:3, :3].T), expected, atol=1e-4)
    np.testing.assert_allclose(after[:3, 3], before[:3, 3], atol=1e-4)  # about the tool tip


def test_invalid_actions_raise_and_change_nothing(exp1_env):
    exp1_env.reset(seed=0)
    env = exp1_env.unwrapped
    exp1_env.step(np.array([0.3, 0, 0, 0, 0, 0], dtype=np.float32))
    state = (
        env.q.copy(),
        env.ee_pos.copy(),
        env.ee_rot.copy(),
        env.steps,
        env.time,
        env.scene.time,
        list(env._shake.queue),
    )
    bad_values = [[np.nan, 0, 0, 0, 0, 0], [0, 0, np.inf, 0, 0, 0], [0, 0, 0, 0, 0, -np.inf]]
    for bad in bad_values:
        with pytest.raises(ValueError, match="NaN or infinity"):
            exp1_env.step(np.array(bad, dtype=np.float32))
    for shape in [(5,), (7,), (0,)]:
        with pytest.raises(ValueError, match="6 values"):
            exp1_env.step(np.zeros(shape, dtype=np.float32))
    np.testing.assert_array_equal(env.q, state[0])
    np.testing.assert_array_equal(env.ee_pos, state[1])
    np.testing.assert_array_equal(env.ee_rot, state[2])
    assert (env.steps, env.time, env.scene.time, list(env._shake.queue)) == state[3:]
    # the PyBullet robot did not move either
    joints = [
        p.getJointState(env.scene.robot, j, physicsClientId=env.scene.client)[0]
        for j in env.scene.joint_indices
    ]
    np.testing.assert_array_equal(joints, state[0])
    # and the episode goes on normally
    _, _, terminated, truncated, _ = exp1_env.step(np.zeros(6, dtype=np.float32))
    assert env.steps == state[3] + 1 and not (terminated or truncated)


def test_step_before_reset_raises():
    env = ReachEnv(scenario="exp1")
    try:
        with pytest.raises(RuntimeError, match="reset"):
            env.step(np.zeros(6, dtype=np.float32))
    finally:
        env.close()


# ---------------------------------------------------------------------- rewards and episode ends
def _step(env, action):
    obs, reward, terminated, truncated, info = env.step(np.asarray(action, dtype=np.float32))
    terms = info["reward_terms"]
    assert set(terms) == {"success", "collision", "distance", "shaking", "out_of_bounds", "exhausted", "progress",
                          "proximity"}
    assert terms["progress"] == terms["proximity"] == 0.0  # not in the paper: off unless weighted
    assert reward == pytest.approx(sum(terms.values()), abs=1e-12)
    assert terms["distance"] == pytest.approx(
        -0.01 * info["distance"] if not info["goal_reached"] else terms["distance"]
    )
    assert terms["shaking"] == pytest.approx(-0.005 * info["n_shakes"])
    return obs, reward, terminated, truncated, info


def test_reward_terms_sum_to_the_reward(exp1_env):
    exp1_env.reset(seed=0)
    env = exp1_env.unwrapped
    goal = np.asarray(env.scenario.goals[0])
    rng = np.random.default_rng(8)
    for _ in range(60):
        _, _, terminated, truncated, info = _step(exp1_env, rng.uniform(-1, 1, 6))
        assert info["reward_terms"]["distance"] == pytest.approx(-0.01 * np.linalg.norm(goal - env.ee_pos))
        if terminated or truncated:
            exp1_env.reset()


def test_shaking_is_penalised(exp1_env):
    """Back and forth along x: the distance to the goal alternates, n_s grows to 9."""
    exp1_env.reset(seed=0)
    n = []
    for k in range(14):
        _, _, _, _, info = _step(exp1_env, [1.0 if k % 2 == 0 else -1.0, 0, 0, 0, 0, 0])
        n.append(info["n_shakes"])
        assert info["reward_terms"]["shaking"] == pytest.approx(-0.005 * n[-1])
    assert n[:3] == [0, 0, 1] and n[-1] == 9


def test_collision_ends_the_episode(exp1_env):
    exp1_env.reset(seed=0)
    for k in range(100):
        _, reward, terminated, truncated, info = _step(exp1_env, [-1, 0, 0, 0, 0, 0])
        if terminated:
            break
    assert terminated and not truncated
    assert info["collision"] and not info["out_of_bounds"] and not info["is_success"]
    assert info["reward_terms"]["collision"] == -10.0
    assert reward == pytest.approx(-10.0 + info["reward_terms"]["distance"] + info["reward_terms"]["shaking"])
    # the tool (radius 2 cm) meets the plate (x = +-2 mm) after about (0.15 - 0.022) / 0.005 steps
    assert 20 <= k + 1 <= 30
    env = exp1_env.unwrapped
    assert env.scene.colliding_obstacles() == [0]
    assert env.scene.colliding_links() == ["rayreach_tool"]  # the tool, not an arm link
    with pytest.raises(RuntimeError):
        exp1_env.step(np.zeros(6, dtype=np.float32))


def test_leaving_the_workspace_ends_the_episode(exp1_env):
    """-y leaves exp1's workspace (y >= 0.3) after 20 steps from y = 0.4."""
    exp1_env.reset(seed=0)
    env = exp1_env.unwrapped
    for k in range(100):
        _, _reward, terminated, truncated, info = _step(exp1_env, [0, -1, 0, 0, 0, 0])
        if terminated:
            break
    assert k + 1 == 21
    assert env.ee_pos[1] < 0.3 <= env.ee_pos[1] + 0.005 + 1e-4
    assert info["out_of_bounds"] and not info["collision"]
    assert info["reward_terms"]["out_of_bounds"] == -10.0
    assert terminated and not truncated


def test_step_budget_truncates_with_exhausted_penalty():
    env = gym.make(UR5_ID, scenario="exp1", max_steps=5)
    try:
        env.reset(seed=0)
        for k in range(5):
            _, reward, terminated, truncated, info = _step(env, [0.2, 0, 0, 0, 0, 0])
            assert not terminated
            if k < 4:
                assert not truncated and info["reward_terms"]["exhausted"] == 0.0
        assert truncated
        assert info["reward_terms"]["exhausted"] == -5.0
        assert reward == pytest.approx(
            -5.0 + info["reward_terms"]["distance"] + info["reward_terms"]["shaking"]
        )
    finally:
        env.close()


def test_success_with_a_large_tolerance():
    env = gym.make(UR5_ID, scenario="exp1", goal_tolerance=0.5)
    try:
        env.reset(seed=0)
        _, reward, terminated, truncated, info = _step(env, np.zeros(6))
        assert terminated and not truncated
        assert info["is_success"] and info["reward_terms"]["success"] == 10.0
        assert reward == pytest.approx(10.0 + info["reward_terms"]["distance"])
    finally:
        env.close()


def test_reaching_the_goal_in_contact_is_a_collision_not_a_success():
    """A 0.5 m tolerance is met at once; the first step pushes the 2 cm tool into a plate 3 mm
    from it, so the episode ends in a collision with no success reward."""
    def plate_beside(ee):
        return ObstacleSpec("box", (ee[0] + 0.025, ee[1], ee[2]), half_extents=(0.002, 0.05, 0.05))

    env = exp1_around_the_tool([plate_beside], goal_tolerance=0.5)
    try:
        env.reset(seed=0)
        _, reward, terminated, _, info = env.step(np.array([1, 0, 0, 0, 0, 0], np.float32))
        assert terminated and info["goal_reached"] and info["collision"] and not info["is_success"]
        assert info["reward_terms"]["success"] == 0.0 and info["reward_terms"]["collision"] == -10.0
        assert reward == pytest.approx(sum(info["reward_terms"].values()))
    finally:
        env.close()


def test_success_needs_distance_below_tolerance():
    """exp1 starts 0.30 m from its goal: a 0.29 m tolerance is not met by standing still."""
    env = gym.make(UR5_ID, scenario="exp1", goal_tolerance=0.29)
    try:
        env.reset(seed=0)
        _, _, terminated, _, info = _step(env, np.zeros(6))
        assert not terminated and not info["is_success"] and info["reward_terms"]["success"] == 0.0
    finally:
        env.close()


def test_exp2_switches_to_the_second_goal():
    env = gym.make(UR5_ID, scenario="exp2", goal_tolerance=0.3)
    try:
        obs, info = env.reset(seed=0)
        goals = np.asarray(env.unwrapped.scenario.goals)
        np.testing.assert_allclose(info["goal"], goals[0])
        obs, _reward, terminated, truncated, info = _step(env, np.zeros(6))
        assert info["goal_reached"] and info["goal_index"] == 1
        assert not terminated and not truncated and not info["is_success"]
        assert info["reward_terms"]["success"] == 10.0
        np.testing.assert_allclose(info["goal"], goals[1])
        ee = env.unwrapped.ee_pos
        np.testing.assert_allclose(obs[6:9], goals[1] - ee, atol=1e-6)  # the observation shows the new goal
        assert obs[12] == pytest.approx(np.linalg.norm(goals[1] - ee), abs=1e-6)
        assert info["distance"] == pytest.approx(np.linalg.norm(goals[1] - ee))
        assert info["distance"] > 0.3
    finally:
        env.close()


# ---------------------------------------------------------------------- determinism, isolation
@pytest.mark.parametrize("robot, scenario", [("ur5", "random"), ("kr16", "random"), ("ur10", "random"), ("ur5", "exp3")])
def test_same_seed_same_actions_same_observations(robot, scenario):
    actions = random_actions(100, seed=9)
    runs = []
    for _ in range(2):
        env = ReachEnv(robot=robot, scenario=scenario)
        try:
            runs.append(rollout(env, seed=123, actions=actions, reset_at=(50,)))
        finally:
            env.close()
    assert len(runs[0]) == len(runs[1])
    for a, b in zip(*runs):
        assert np.array_equal(a, b)
    # and a different seed gives a different world
    if scenario == "random":
        env = ReachEnv(robot=robot, scenario=scenario)
        try:
            other = rollout(env, seed=124, actions=actions[:1])
        finally:
            env.close()
        assert not np.array_equal(other[0], runs[0][0])


def test_reset_with_the_same_seed_repeats_in_one_env():
    env = ReachEnv(robot="ur5", scenario="exp3")
    try:
        actions = random_actions(30, seed=10)
        first = rollout(env, seed=5, actions=actions)
        second = rollout(env, seed=5, actions=actions)
        for a, b in zip(first, second):
            assert np.array_equal(a, b)
    finally:
        env.close()


def test_two_robots_in_one_process_do_not_interfere():
    actions = random_actions(60, seed=11)
    alone = {}
    for robot in ("ur5", "kr16"):
        env = ReachEnv(robot=robot)
        try:
            alone[robot] = rollout(env, seed=7, actions=actions)
        finally:
            env.close()
    envs = {robot: ReachEnv(robot=robot) for robot in ("ur5", "kr16")}
    try:
        assert envs["ur5"].scene.client != envs["kr16"].scene.client
        together = {robot: [env.reset(seed=7)[0]] for robot, env in envs.items()}
        for a in actions:
            for robot, env in envs.items():  # interleaved
                obs, _, terminated, truncated, _ = env.step(a)
                together[robot].append(obs)
                if terminated or truncated:
                    together[robot].append(env.reset()[0])
        for robot in envs:
            assert len(together[robot]) == len(alone[robot])
            for a_, b_ in zip(together[robot], alone[robot]):
                assert np.array_equal(a_, b_)
    finally:
        for env in envs.values():
            env.close()


# ---------------------------------------------------------------------- moving obstacle
def test_exp3_plate_moves_0_2_m_per_s():
    env = ReachEnv(scenario="exp3")
    try:
        env.reset(seed=0)
        scene = env.scene
        start = np.asarray(env.scenario.obstacles[0].position)
        np.testing.assert_allclose(scene.obstacle_positions()[0], start)
        # a vertical ray just inside the plate's trailing edge (y = 0.35) sees it at t = 0 ...
        origin = np.array([[-0.3, 0.352, 0.2]])
        up = np.array([[0.0, 0.0, 1.0]])
        for backend in ("numpy", "bullet"):
            assert scene.caster(backend).cast(origin, up, 0.4)[0] == pytest.approx(0.098 / 0.4, abs=1e-6)
        for k in range(1, 11):
            _, _, terminated, _, info = env.step(np.zeros(6, dtype=np.float32))
            assert not terminated
            assert info["time"] == pytest.approx(k / 240)
            np.testing.assert_allclose(
                scene.obstacle_positions()[0], start + [0.0, 0.2 * k / 240, 0.0], atol=1e-12
            )
        body_pos, _ = p.getBasePositionAndOrientation(scene._obstacle_ids[0], physicsClientId=scene.client)
        np.testing.assert_allclose(body_pos, start + [0.0, 0.2 * 10 / 240, 0.0], atol=1e-9)
        # ... and no longer after 10 steps (8.3 mm), in both backends
        for backend in ("numpy", "bullet"):
            assert scene.caster(backend).cast(origin, up, 0.4)[0] == 1.0
        # a reset puts it back
        env.reset()
        np.testing.assert_allclose(scene.obstacle_positions()[0], start)
        assert env.caster.cast(origin, up, 0.4)[0] < 1.0
    finally:
        env.close()


# ---------------------------------------------------------------------- rendering, construction errors
def test_render_rgb_array():
    env = gym.make(UR5_ID, scenario="exp1", render_mode="rgb_array")
    try:
        env.reset(seed=0)
        image = env.render()
        assert image.ndim == 3 and image.shape[2] == 3 and image.dtype == np.uint8
        assert image.shape[0] > 10 and image.shape[1] > 10
        assert image.reshape(-1, 3).std(axis=0).max() > 5.0
        assert len(np.unique(image.reshape(-1, 3), axis=0)) > 10
    finally:
        env.close()


def test_render_mode_is_validated():
    with pytest.raises(ValueError, match="render_mode"):
        ReachEnv(robot="ur5", render_mode="video")


def test_unknown_robot_lists_the_known_ones():
    with pytest.raises(ValueError, match="kr16, ur10, ur5"):
        ReachEnv(robot="ur3")


def test_unknown_option_lists_valid_options():
    with pytest.raises(TypeError) as err:
        ReachEnv(robot="ur5", goal_tolerence=0.1)
    message = str(err.value)
    assert "goal_tolerence" in message
    for option in ("goal_tolerance", "max_steps", "control_period", "ray_backend"):
        assert option in message


def test_option_values_are_validated():
    with pytest.raises(ValueError, match="goal_tolerance"):
        ReachEnv(robot="ur5", goal_tolerance=0.0)
    with pytest.raises(ValueError, match="max_steps"):
        ReachEnv(robot="ur5", max_steps=0)


def test_random_world_needs_a_robot():
    with pytest.raises(ValueError, match="robot"):
        ReachEnv()


def test_bullet_backend_env_matches_numpy_backend_in_exp1():
    """The env's observations with either backend agree to Bullet's tolerance (see
    test_sensors): here the rays meet the plate nearly head-on."""
    envs = [ReachEnv(scenario="exp1", ray_backend=b) for b in ("numpy", "bullet")]
    try:
        obs = [e.reset(seed=0)[0] for e in envs]
        for a in random_actions(20, seed=12, scale=0.5):
            stepped = [e.step(a)[0] for e in envs]
        obs += stepped
        np.testing.assert_array_equal(obs[0][:13], obs[1][:13])
        assert np.abs(obs[0][13:] - obs[1][13:]).max() < 0.01
        assert np.abs(obs[2][13:] - obs[3][13:]).max() < 0.01
        assert np.any(obs[0][13:] < 1)
    finally:
        for e in envs:
            e.close()


def test_set_goal_tolerance():
    env = ReachEnv(scenario="exp1")
    try:
        env.set_goal_tolerance(0.5)
        assert env.config.goal_tolerance == 0.5
        env.reset(seed=0)
        _, _, terminated, _, info = env.step(np.zeros(6, dtype=np.float32))
        assert terminated and info["is_success"]
        with pytest.raises(ValueError):
            env.set_goal_tolerance(-1.0)
    finally:
        env.close()


def test_action_space():
    env = ReachEnv(scenario="exp1")
    try:
        space = env.action_space
        assert space.shape == (6,) and space.dtype == np.float32
        np.testing.assert_array_equal(space.low, -1.0)
        np.testing.assert_array_equal(space.high, 1.0)
        assert math.isclose(env.spec_robot.ee_step, 0.005) and math.isclose(env.spec_robot.rot_step, 0.005)
    finally:
        env.close()


def test_rotvec_helper_used_by_actions_is_consistent():
    """The action rotation is rotvec_to_matrix(delta) applied on the left (world axes)."""
    delta = np.array([0.0, 0.0, 0.005])
    np.testing.assert_allclose(matrix_to_rotvec(rotvec_to_matrix(delta)), delta, atol=1e-15)


def test_true_goal_share_plays_that_share_of_random_episodes_at_the_true_size():
    """With an enormous curriculum goal every episode but the true-size ones ends at once."""
    env = ReachEnv(robot="ur5", goal_tolerance=5.0, true_goal_share=0.5, true_goal_tolerance=0.01)
    try:
        flags = []
        for seed in range(40):
            env.reset(seed=seed)
            _, _, terminated, _, info = env.step(np.zeros(6, dtype=np.float32))
            assert info["goal_tolerance"] == (0.01 if info["true_goal_episode"] else 5.0)
            assert info["is_success"] == (not info["true_goal_episode"])
            flags.append(info["true_goal_episode"])
        assert 10 <= sum(flags) <= 30
    finally:
        env.close()


def test_true_goal_share_never_applies_to_fixed_scenarios_and_is_validated():
    env = ReachEnv(scenario="exp1", goal_tolerance=0.5, true_goal_share=1.0)
    try:
        env.reset(seed=0)
        _, _, _, _, info = env.step(np.zeros(6, dtype=np.float32))
        assert info["is_success"] and not info["true_goal_episode"] and info["goal_tolerance"] == 0.5
    finally:
        env.close()
    with pytest.raises(ValueError, match="true_goal_share"):
        ReachEnv(robot="ur5", true_goal_share=1.5)
