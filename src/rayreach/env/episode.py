"""One episode loop for every caller: the executor, ``rollout``, demonstrations and the demo.

It reads what acted from ``info["acting"]`` where a wrapper (``rayreach.acting.ActingEnv``) puts
it there, and imports nothing of the acting layers."""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Any, Callable

import gymnasium as gym
import numpy as np

from rayreach.env.reach import episode_outcome

Act = Callable[[np.ndarray, dict[str, Any]], "np.ndarray | None"]
"""The action for an observation, given the last step's (or reset's) info; None ends the
episode early (a scripted sequence that has run out)."""


@dataclass
class EpisodeRecord:
    """What one episode did."""

    info: dict[str, Any]
    """The last step's info (reset's if no step was taken)."""
    ee_path: np.ndarray
    """End-effector positions, the start first, m (steps + 1, 3)."""
    joint_path: np.ndarray
    """Joint angles, the start first, rad (steps + 1, 6)."""
    total_reward: float
    compute_time: float
    """Seconds spent choosing actions and stepping."""
    sources: Counter = field(default_factory=Counter)
    """Steps by what chose the executed motion (``info["acting"]["source"]``; ``policy`` where
    nothing acted between the action and the arm)."""
    held_by: Counter = field(default_factory=Counter)
    """Held steps by what held the arm (``info["acting"]["held_by"]``)."""

    @property
    def steps(self) -> int:
        return len(self.ee_path) - 1

    @property
    def outcome(self) -> str:
        return episode_outcome(self.info)

    @property
    def path_length(self) -> float:
        """End-effector path length, m."""
        return float(np.linalg.norm(np.diff(self.ee_path, axis=0), axis=1).sum()) if self.steps else 0.0

    @property
    def acting_share(self) -> dict[str, float]:
        """The share of steps by source, summing to 1 (empty for an episode of no steps)."""
        return share(self.sources)


def share(sources: Counter) -> dict[str, float]:
    """``sources`` (steps by source) as shares summing to 1, ``policy`` first."""
    total = sum(sources.values())
    if not total:
        return {}
    names = ["policy", *sorted(k for k in sources if k != "policy")]
    return {name: sources.get(name, 0) / total for name in names}


def run_episode(env: gym.Env, act: Act, seed: int | None = None,
                on_step: Callable[[np.ndarray, gym.Env], None] | None = None,
                start: tuple[np.ndarray, dict[str, Any]] | None = None) -> EpisodeRecord:
    """Reset ``env`` (with ``seed``) and step it with ``act`` until the episode ends.
    ``on_step(obs, env)`` sees each observation before it is acted on; ``start``: the
    (observation, info) of a reset already made, to play that episode instead."""
    base = env.unwrapped
    obs, info = env.reset(seed=seed) if start is None else start
    ee, joints = [info["ee_position"]], [base.q.copy()]
    total, compute, sources, held_by = 0.0, 0.0, Counter(), Counter()
    while True:
        if on_step is not None:
            on_step(obs, env)
        t0 = time.perf_counter()
        action = act(obs, info)
        if action is None:
            break
        obs, reward, terminated, truncated, info = env.step(action)
        compute += time.perf_counter() - t0
        total += reward
        ee.append(info["ee_position"])
        joints.append(base.q.copy())
        acting = info.get("acting", {})
        sources[acting.get("source", "policy")] += 1
        if acting.get("held"):
            held_by[acting.get("held_by", "")] += 1
        if terminated or truncated:
            break
    return EpisodeRecord(info, np.asarray(ee), np.asarray(joints), total, compute, sources, held_by)
