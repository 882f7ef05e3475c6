"""The privileged teacher and its distillation: the teacher's observation is the student's
with the privileged part after it, only the batched env computes it, and DAgger fits a
student that sees only the prefix to the teacher's actions, saved as a checkpoint that PPO
fine-tunes and a ReachEnv can play."""

from __future__ import annotations

import csv
from dataclasses import replace

import numpy as np
import pytest
import torch

from rayreach.env.observation import ObservationConfig
from rayreach.learning.bundles import read_bundle_meta
from rayreach.learning.distill import Aggregate, DistillConfig, beta, distill, student_normalization
from rayreach.learning.train import TrainConfig, config_from_meta, train, with_envs

TEACHER = replace(ObservationConfig.planner(), privileged=True)


def _small(**changes) -> TrainConfig:
    return replace(with_envs(TrainConfig(observation=TEACHER), 4), workers=1, max_episode_steps=32,
                   checkpoint_every=10**9, **changes)


def test_beta_falls_from_the_teacher_to_the_student():
    assert beta(0, 100) == 1.0 and beta(50, 100) == 0.5 and beta(100, 100) == 0.0 and beta(500, 100) == 0.0
    assert beta(0, 0) == 0.0  # the student drives from the start


def test_the_aggregate_keeps_the_latest_states():
    buffer = Aggregate(5, 2, 1)
    for k in range(3):
        buffer.add(np.full((2, 2), k), np.full((2, 1), k), np.full(2, k))
    assert buffer.size == 5
    assert sorted(buffer.obs[:, 0].tolist()) == [0, 1, 1, 2, 2]  # one of the oldest dropped
    obs, action, value = buffer.sample(100, np.random.default_rng(0))
    assert len(obs) == 5 and np.array_equal(obs[:, 0], action[:, 0]) and np.array_equal(obs[:, 0], value)


def test_the_student_normalisation_is_the_teachers_prefix():
    arrays = {"obs_mean": np.arange(6.0), "obs_var": np.arange(6.0) + 1, "clip_obs": np.array(10.0)}
    student = student_normalization(arrays, 4)
    assert np.array_equal(student["obs_mean"], [0, 1, 2, 3]) and np.array_equal(student["obs_var"], [1, 2, 3, 4])
    assert arrays["obs_mean"].shape == (6,)  # the teacher's left whole


def test_only_the_batched_env_computes_the_privileged_part():
    from rayreach.env.batched import BatchedReachEnv
    from rayreach.env.reach import EnvConfig, ReachEnv

    with pytest.raises(ValueError, match="BatchedReachEnv"):
        ReachEnv(robot="ur5", config=EnvConfig(observation=TEACHER))
    with pytest.raises(ValueError, match="batched"):
        TrainConfig(observation=TEACHER, vec_env="workers")
    teacher = BatchedReachEnv("ur5", 2, config=EnvConfig(observation=TEACHER), seed=5)
    student = BatchedReachEnv("ur5", 2, config=EnvConfig(observation=TEACHER.deployable), seed=5)
    try:
        a, b = teacher.reset(), student.reset()
        assert a.shape[1] == b.shape[1] + teacher.privileged.shape[1] and teacher.observation_space.shape == a.shape[1:]
        rng = np.random.default_rng(0)
        for _ in range(20):
            action = rng.uniform(-1, 1, (2, 6))
            a, b = teacher.step(action)[0], student.step(action)[0]
            assert np.array_equal(a[:, : b.shape[1]], b)  # the same worlds, the student's values first
    finally:
        teacher.close()
        student.close()


def test_dagger_fits_the_student_to_the_teacher_and_ppo_fine_tunes_it(tmp_path):
    from stable_baselines3 import PPO

    from rayreach.evaluate.rollout import rollout
    from rayreach.learning.bundles import save_bundle
    from rayreach.learning.policy import load_policy

    run = tmp_path / "teacher"
    train(_small(timesteps=256), run)
    # a teacher whose actions lie far from an untrained student's (which are near 0)
    teacher = PPO.load(str(run / "model.zip"))
    with torch.no_grad():
        teacher.policy.action_net.bias.fill_(0.6)
    meta, norm = read_bundle_meta(run / "model.zip")
    save_bundle(teacher, run / "model.zip", meta, norm)

    out = tmp_path / "student"
    config = DistillConfig(steps=4 * 8 * 20, envs=4, rollout=8, teacher_steps=64, minibatch=64, fits=20,
                           learning_rate=3e-3)
    distill(run / "model.zip", out, config, progress=False)
    with (out / "distill.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert [float(r["beta"]) for r in rows[:3]] == [1.0, 0.5, 0.0]
    assert int(rows[-1]["student_episodes"]) > 0  # the student drove once beta fell
    # an untrained student's actions are near 0, the teacher's near 0.6: a squared error of 0.36
    assert float(rows[0]["action_loss"]) > 0.02 and float(rows[-1]["action_loss"]) < 0.005

    student_meta, student_norm = read_bundle_meta(out / "checkpoint.zip")
    size = student_meta["obs_shape"][0]
    assert student_meta["kind"] == "checkpoint" and student_meta["timesteps"] == 0
    assert config_from_meta(student_meta).observation == TEACHER.deployable
    assert size == len(student_norm["obs_mean"]) < len(norm["obs_mean"])
    assert np.array_equal(student_norm["obs_mean"], norm["obs_mean"][:size])
    assert student_meta["state"]["distilled"]["steps"] == config.steps
    assert (out / "distill.png").stat().st_size > 1000  # the curve, drawn

    train(replace(config_from_meta(student_meta), timesteps=256), out, resume=True)
    final, _ = read_bundle_meta(out / "model.zip")
    assert final["timesteps"] == 256 and final["state"]["distilled"]["steps"] == config.steps
    assert load_policy(out / "model.zip").observation == TEACHER.deployable
    assert rollout(out / "model.zip", "random", episodes=1, progress=False).episodes == 1  # in a ReachEnv
