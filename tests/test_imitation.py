"""The imitation term beside PPO (``rayreach.learning.imitation``)."""

import shutil
from dataclasses import replace

import numpy as np
import pytest

from rayreach.learning.imitation import demos_name, load_demos, save_demos
from rayreach.learning.policy import load_policy
from rayreach.learning.train import CHECKPOINT, TrainConfig, train, with_envs


def tiny(**changes) -> TrainConfig:
    """64 decisions a rollout, no validation."""
    settings = dict(workers=1, max_episode_steps=32, timesteps=128, checkpoint_every=64, validate_every=0)
    return replace(with_envs(TrainConfig(n_steps=16), 4), **{**settings, **changes})


def _observations(config: TrainConfig, n: int) -> np.ndarray:
    from rayreach.env.reach import ReachEnv

    env = ReachEnv(robot=config.robot, observation=config.observation)
    try:
        return np.asarray([env.reset(seed=s)[0] for s in range(n)])
    finally:
        env.close()


def _error(run, observations, labels) -> float:
    policy = load_policy(run / CHECKPOINT)
    return float(np.mean([(policy.act(o) - y) ** 2 for o, y in zip(observations, labels)]))


def test_demonstrations_are_kept_per_clone_and_their_absence_is_named(tmp_path):
    save_demos(tmp_path, "shelf", [np.zeros(3)] * 2, [np.ones(2)] * 2)
    save_demos(tmp_path, "goal_box", [np.ones(3)], [np.zeros(2)])
    observations, labels = load_demos(tmp_path)
    assert observations.shape == (3, 3) and labels.shape == (3, 2)
    assert (tmp_path / demos_name("shelf")).exists()
    with pytest.raises(FileNotFoundError, match=r"no demonstrations \(demos-\*.npz\) in .*clone"):
        load_demos(tmp_path / "elsewhere")
    with pytest.raises(FileNotFoundError, match="no demonstrations"):
        train(tiny(imitation_steps=5), tmp_path / "run")


def test_the_term_pulls_the_actor_to_the_labels_and_waits_while_the_actor_is_held(tmp_path):
    """From one checkpoint, 64 more decisions with the term bring the actor's actions on the
    demonstrations closer to the labels than without; during a critic warm-up they stay."""
    config = tiny()
    train(config, tmp_path / "start")
    observations = _observations(config, 24)
    labels = np.tile(np.float32([0.6, -0.6, 0.6, -0.6, 0.6, -0.6]), (len(observations), 1))
    before = _error(tmp_path / "start", observations, labels)
    for name in ("with", "without", "held"):
        shutil.copytree(tmp_path / "start", tmp_path / name)
        save_demos(tmp_path / name, "goal_slot", list(observations), list(labels))
    train(replace(config, timesteps=192, imitation_steps=40), tmp_path / "with", resume=True,
          resume_overrides={"imitation_steps": 40})
    train(replace(config, timesteps=192), tmp_path / "without", resume=True)
    train(replace(config, timesteps=192), tmp_path / "held", resume=True, resume_overrides={"imitation_steps": 40},
          critic_warmup=10**6)
    pulled, left = _error(tmp_path / "with", observations, labels), _error(tmp_path / "without", observations, labels)
    assert pulled < 0.5 * min(before, left)
    # held: only the observation statistics moved
    assert _error(tmp_path / "held", observations, labels) == pytest.approx(before, rel=0.01)
