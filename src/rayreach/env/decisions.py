"""A policy that decides every ``period`` control steps: its action held in between.

The paper's agent decides at the control rate, 240 times a second, each step at most 5 mm.
At that rate a cover that has to pass before the goal can be reached is hundreds of
decisions away, and every decision moves the arm too little for its own effect to stand out
of the noise. Holding each action for ``period`` control steps keeps the motion, the
collision checks and the rays at the control rate and lets the policy decide less often
(the decimation of legged-robot training; docs/training.md). Not in the paper.

``DecisionPeriod`` wraps a stable-baselines3 ``VecEnv`` (the batched worlds) for training:
one of its steps is ``period`` steps of the worlds with the same action, the rewards summed.
A world whose episode ends within a step reports that end (its last info, observation and
reward) and stands still for the step's rest, so its next episode starts on a decision.
``HeldAction`` does the same for one ``ReachEnv`` (the per-world training worlds), and
``ActingPolicy`` holds the action the same way where a policy acts.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvWrapper


def check_period(period: int) -> int:
    """``period`` as an int >= 1, or an error that says what is valid."""
    if int(period) != period or period < 1:
        raise ValueError(f"decision_period must be a whole number of control steps >= 1, got {period!r}")
    return int(period)


class DecisionPeriod(VecEnvWrapper):
    """``venv``'s worlds deciding every ``period`` control steps (see the module docstring)."""

    def __init__(self, venv: VecEnv, period: int) -> None:
        super().__init__(venv)
        self.period = check_period(period)
        self._actions = np.zeros((venv.num_envs,) + venv.action_space.shape, dtype=np.float32)

    def reset(self) -> np.ndarray:
        return self.venv.reset()

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, dtype=np.float32).reshape(self._actions.shape)

    def step_wait(self):
        n = self.num_envs
        rewards = np.zeros(n, dtype=np.float32)
        ended = np.zeros(n, dtype=bool)
        infos: list[dict] = [{} for _ in range(n)]
        still = np.zeros_like(self._actions)
        obs = None
        for _ in range(self.period):
            obs, step_rewards, dones, step_infos = self.venv.step(np.where(ended[:, None], still, self._actions))
            rewards += np.where(ended, 0.0, step_rewards).astype(np.float32)
            for i in np.flatnonzero(dones & ~ended):
                infos[i] = step_infos[i]
            ended |= dones
            if ended.all():
                break
        return obs, rewards, ended, infos


class HeldAction(gym.Wrapper):
    """One ``ReachEnv`` (or ``ActingEnv``) deciding every ``period`` control steps: a step is
    ``period`` steps of ``env`` with the same action, the rewards summed, until its episode
    ends. The info is the last control step's."""

    def __init__(self, env: gym.Env, period: int) -> None:
        super().__init__(env)
        self.period = check_period(period)

    def step(self, action):
        total = 0.0
        for _ in range(self.period):
            obs, reward, terminated, truncated, info = self.env.step(action)
            total += float(reward)
            if terminated or truncated:
                break
        return obs, total, terminated, truncated, info
