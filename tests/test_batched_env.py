"""The batched environment is N ``ReachEnv``s: same observations, rewards and episode ends."""

from __future__ import annotations

import numpy as np
import pytest

from rayreach.env.batched import BatchedReachEnv
from rayreach.env.reach import ReachEnv, episode_outcome
from rayreach.scenarios.schema import ObstacleSpec
from rayreach.sim.batch_obstacles import ObstacleBatch

SEED = 100


def _towards_goal(obs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Actions that head for the goal through the obstacles, with noise: episodes end in every way."""
    drive = np.clip(obs[:, 6:9] / 0.005, -1, 1)
    noise = rng.normal(0.0, 0.6, (len(obs), 6))
    return np.clip(np.concatenate((drive, np.zeros((len(obs), 3))), axis=1) + noise, -1, 1).astype(np.float32)


def _compare(robot: str, scenario: str, n_worlds: int, episodes: int, seen: list | None = None,
             **overrides) -> dict[str, int]:
    """Step both through the same worlds and actions until ``episodes`` episodes ended; every
    observation, reward and episode end must agree. Returns the episode outcomes; ``seen``
    gets the batched env's observations."""
    batched = BatchedReachEnv(robot, n_worlds, scenario, seed=SEED, **overrides)
    singles = [ReachEnv(robot=robot, scenario=scenario, **overrides) for _ in range(n_worlds)]
    rng = np.random.default_rng(0)
    outcomes: dict[str, int] = {}
    try:
        obs = batched.reset()
        single_obs = np.array([env.reset(seed=SEED + i)[0] for i, env in enumerate(singles)])
        np.testing.assert_allclose(obs, single_obs, atol=1e-6, rtol=0)
        while sum(outcomes.values()) < episodes:
            actions = _towards_goal(obs, rng)
            obs, rewards, dones, infos = batched.step(actions)
            if seen is not None:
                seen.append(obs.copy())
            for i, env in enumerate(singles):
                o, r, terminated, truncated, info = env.step(actions[i])
                assert dones[i] == (terminated or truncated), f"world {i}: episode end differs"
                assert abs(float(rewards[i]) - r) <= 1e-6 * max(1.0, abs(r)), f"world {i}: reward {rewards[i]} vs {r}"
                if dones[i]:
                    last = infos[i]
                    np.testing.assert_allclose(last["terminal_observation"], o, atol=1e-6, rtol=0)
                    assert episode_outcome(last) == episode_outcome(info)
                    assert last["TimeLimit.truncated"] == (truncated and not terminated)
                    for key, value in info["episode_reward_terms"].items():
                        assert last["episode_reward_terms"][key] == pytest.approx(value, abs=1e-6)
                    outcomes[episode_outcome(info)] = outcomes.get(episode_outcome(info), 0) + 1
                    o, _ = env.reset()
                else:
                    assert infos[i] == {}
                np.testing.assert_allclose(obs[i], o, atol=1e-6, rtol=0, err_msg=f"world {i}")
    finally:
        batched.close()
        for env in singles:
            env.close()
    return outcomes


@pytest.mark.parametrize("robot", ["ur5", "kr16", "ur10"])
def test_random_worlds_step_as_reach_env_does(robot):
    """>= 100 episodes per robot on random worlds of 3 obstacles (moving plates, the KR16's
    shelf), ended by success, collision, leaving the workspace and the step budget."""
    outcomes = _compare(robot, "random", 16, 100, max_steps=100, goal_tolerance=0.1)
    assert sum(outcomes.values()) >= 100
    assert {"success", "collision", "timeout"} <= set(outcomes), outcomes


@pytest.mark.parametrize("scenario", ["exp2", "exp4"])
def test_fixed_scenarios_step_as_reach_env_does(scenario):
    outcomes = _compare(None, scenario, 4, 12, max_steps=150)
    assert sum(outcomes.values()) >= 12


def test_ppo_learns_on_it():
    from stable_baselines3 import PPO

    env = BatchedReachEnv("ur5", 8, seed=0, max_steps=20)
    try:
        model = PPO("MlpPolicy", env, n_steps=8, batch_size=32, n_epochs=1, seed=0)
        model.learn(64)
        assert model.num_timesteps == 64
    finally:
        env.close()


def test_curriculum_setters_reach_the_next_episode():
    env = BatchedReachEnv("ur5", 2, seed=0, max_steps=3)
    try:
        env.reset()
        env.env_method("set_goal_tolerance", 0.07)
        env.env_method("set_n_obstacles", 1, indices=[1])
        for _ in range(3):
            _, _, dones, infos = env.step(np.zeros((2, 6), dtype=np.float32))
        assert dones.all() and infos[0]["goal_tolerance"] != 0.07  # the episode that ended kept its own
        assert env.tolerance.tolist() == [0.07, 0.07]
        assert env.obstacles.boxes.count[1] + env.obstacles.spheres.count[1] <= 2  # a goal slot is two plates
        with pytest.raises(AttributeError, match="set_goal_tolerance"):
            env.env_method("render")
    finally:
        env.close()


def test_bad_actions_and_shapes_are_refused():
    env = BatchedReachEnv("ur5", 2, seed=0)
    try:
        env.reset()
        with pytest.raises(ValueError, match=r"\(2, 6\)"):
            env.step(np.zeros((2, 5), dtype=np.float32))
        bad = np.zeros((2, 6), dtype=np.float32)
        bad[1, 2] = np.nan
        with pytest.raises(ValueError, match=r"worlds \[1\]"):
            env.step(bad)
    finally:
        env.close()


def test_obstacle_batch_moves_as_obstacle_spec_does():
    plate = ObstacleSpec("box", (0.3, 0.2, 0.5), half_extents=(0.05, 0.05, 0.002), velocity=(0.1, -0.05, 0.0),
                         travel=0.2)
    ball = ObstacleSpec("sphere", (0.0, 0.4, 0.6), radius=0.04, velocity=(0.0, 0.0, 0.15))
    batch = ObstacleBatch(3)
    batch.set_world(1, [plate, ball])
    times = np.array([0.0, 3.7, 0.0])
    batch.at_time(times)
    np.testing.assert_allclose(batch.boxes.pos[1, 0], plate.position_at(3.7), atol=1e-12)
    np.testing.assert_allclose(batch.spheres.pos[1, 0], ball.position_at(3.7), atol=1e-12)
    assert batch.boxes.count.tolist() == [0, 1, 0]
    with pytest.raises(ValueError, match="box and sphere"):
        batch.set_world(0, [ObstacleSpec("cylinder", (0, 0, 0), radius=0.1, height=0.2)])


def test_gymnasium_make_vec_gives_the_batched_worlds():
    import gymnasium as gym

    import rayreach  # noqa: F401  (registers the ids)

    envs = gym.make_vec("rayreach/Reach-UR5-v0", num_envs=3, vectorization_mode="vector_entry_point", max_steps=4)
    try:
        obs, _ = envs.reset(seed=SEED)
        single = ReachEnv(robot="ur5", scenario="random")
        np.testing.assert_allclose(obs[2], single.reset(seed=SEED + 2)[0], atol=1e-6)
        single.close()
        for _ in range(4):
            obs, rewards, terminated, truncated, infos = envs.step(np.zeros((3, 6), dtype=np.float32))
        assert obs.shape == (3, 142) and (terminated | truncated).all()
        assert infos["_final_obs"].all() and infos["final_obs"][0].shape == (142,)
    finally:
        envs.close()


def test_bench_env_batched_prints_both_rates_their_ratio_stages_and_resets(capsys):
    import json

    from rayreach.cli import main
    from rayreach.env.batched import STAGES

    assert main(["bench-env", "--robot", "ur5", "--scenario", "random", "--batched", "4", "--steps", "24",
                 "--rounds", "1", "--json"]) == 0
    record = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    rates = record["steps_per_s"]
    assert set(rates) == {"single", "batched"} and record["steps"] == 24
    assert record["speedup"] == pytest.approx(rates["batched"] / rates["single"], rel=0.01)
    assert set(record["us_per_world_step"]) == set(STAGES) and set(record["ms_per_reset"]) == {"single", "batched"}
    assert main(["bench-env", "--batched", "0"]) == 2
    assert "number of worlds" in capsys.readouterr().err


def test_per_world_attributes_and_refused_options():
    env = BatchedReachEnv("ur5", 3, seed=0)
    try:
        env.env_method("set_n_obstacles", 2, indices=[1])
        assert env.get_attr("n_obstacles") == [3, 2, 3] and env.get_attr("random", indices=[0]) == [True]
    finally:
        env.close()
    with pytest.raises(ValueError, match="PyBullet's rays"):
        BatchedReachEnv("ur5", 1, ray_backend="bullet")


def test_the_planner_observation_steps_as_reach_env_does():
    from rayreach.env.observation import ObservationConfig

    outcomes = _compare("ur5", "random", 8, 30, max_steps=100, goal_tolerance=0.1,
                        observation=ObservationConfig.planner())
    assert sum(outcomes.values()) >= 30


def test_broad_worlds_step_as_reach_env_does():
    from rayreach.env.observation import ObservationConfig

    outcomes = _compare("ur5", "broad", 4, 8, max_steps=60, goal_tolerance=0.1, observation=ObservationConfig.planner())
    assert sum(outcomes.values()) >= 8


def test_a_collision_margin_steps_as_reach_env_does():
    """Training's margin (``EnvConfig.collision_margin``): both envs end the same episodes as
    collisions, the broad phase looking that much further."""
    outcomes = _compare("ur5", "random", 6, 16, max_steps=80, goal_tolerance=0.1, collision_margin=0.03)
    assert outcomes.get("collision", 0) >= 3


@pytest.mark.parametrize("robot, scenario", [("kr16", "random"), ("ur10", "random"), (None, "exp2")])
def test_progress_round_the_obstacles_steps_as_reach_env_does(robot, scenario):
    """The progress term measured along the goal field (``goal_field``): both envs build the
    same field at each reset and goal change, and sum the same rewards."""
    from rayreach.env.rewards import RewardWeights

    rewards = RewardWeights(progress=10.0, progress_around_obstacles=True)
    outcomes = _compare(robot, scenario, 6, 20, max_steps=80, goal_tolerance=0.1, rewards=rewards)
    assert sum(outcomes.values()) >= 20


@pytest.mark.parametrize("slanted, sightings, goal_sight", [(False, 0, False), (True, 0, False), (False, 4, False),
                                                          (True, 3, True), (False, 0, True)])
def test_rays_beyond_the_129_step_as_reach_env_does(slanted, sightings, goal_sight):
    """Goal-cover and plate worlds, where the tip-back rays see the plate over the goal, the
    slanted ones plates across the tool and the goal rays the cover between the tool and the
    goal; the remembered sightings take the nearest of every ray the policy reads."""
    from dataclasses import replace

    from rayreach.env.observation import ObservationConfig
    from rayreach.scenarios.random_world import RandomWorldConfig

    observation = replace(ObservationConfig.planner(), slanted=slanted, sightings=sightings, goal_sight=goal_sight)
    seen: list[np.ndarray] = []
    outcomes = _compare("ur5", "random", 6, 12, max_steps=100, goal_tolerance=0.1, observation=observation,
                        random_world=RandomWorldConfig(n_obstacles=1, kinds=("goal_cover", "plate")), seen=seen)
    assert sum(outcomes.values()) >= 12
    if goal_sight:  # a cover stood between the tool and the goal
        assert (np.array(seen)[:, :, -3:] < 1).any()


@pytest.mark.parametrize("robot", ["ur5", "kr16"])
def test_rays_along_the_arm_step_as_reach_env_does(robot):
    """Broad worlds, whose tables and shelves lie beside the upper arm and the forearm: the
    batched env casts the 64 rays round them as ``ReachEnv`` does, and they see something."""
    from dataclasses import replace

    from rayreach.env.observation import OBS_SIZE, ObservationConfig
    from rayreach.sim.sensors import N_ARM, N_RAYS

    observation = replace(ObservationConfig.planner(), arm_rays=True, sightings=2)
    seen: list[np.ndarray] = []
    outcomes = _compare(robot, "broad", 4, 6, max_steps=60, goal_tolerance=0.1, observation=observation, seen=seen)
    assert sum(outcomes.values()) >= 6
    start = OBS_SIZE + replace(observation, arm_rays=False, sightings=0).extra_size(N_RAYS)
    assert (np.array(seen)[:, :, start:start + N_ARM] < 1).any()


def test_sightings_of_a_plate_many_rays_meet_at_one_distance_step_as_reach_env_does():
    """A plate square to the tool over its tip: a whole ring of tip-back rays meets it at
    one distance, and both envs must choose the same of them as the nearest sighting."""
    from dataclasses import replace

    from rayreach.env.observation import ObservationConfig
    from scenes import plate_over_the_tip

    observation = replace(ObservationConfig.planner(), sightings=2)
    for back, out in ((0.05, 0.1), (0.08, 0.12)):
        outcomes = _compare(None, plate_over_the_tip(back=back, centre_out=out, half=0.07), 2, 2, max_steps=30,
                            goal_tolerance=0.1, observation=observation)
        assert sum(outcomes.values()) >= 2
