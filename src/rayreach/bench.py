"""Environment throughput, measured side by side for both ray backends in one process."""

from __future__ import annotations

import time
from dataclasses import dataclass

from rayreach.env import ReachEnv
from rayreach.scene import RAY_BACKENDS


@dataclass(frozen=True)
class BenchResult:
    steps_per_s: dict[str, float]
    steps: int
    rounds: int

    @property
    def speedup(self) -> float:
        """Default (numpy) backend over PyBullet's ``rayTestBatch``."""
        return self.steps_per_s["numpy"] / self.steps_per_s["bullet"]


def bench_env(robot: str, scenario: str, steps: int = 3000, rounds: int = 3, seed: int = 0) -> BenchResult:
    """Steps per second with uniformly random actions (episodes reset as they end).

    Each backend runs ``steps`` steps split into ``rounds`` interleaved blocks, so a
    background load on this machine hits both alike; resets are included in the time.
    """
    backends = [b for b in RAY_BACKENDS if b != "auto"]
    envs = {b: ReachEnv(robot=robot, scenario=scenario, ray_backend=b) for b in backends}
    elapsed = dict.fromkeys(backends, 0.0)
    block = max(1, steps // rounds)
    try:
        for b, env in envs.items():
            env.reset(seed=seed)
            env.action_space.seed(seed)
        for _ in range(rounds):
            for b, env in envs.items():
                actions = [env.action_space.sample() for _ in range(block)]
                t0 = time.perf_counter()
                for a in actions:
                    _, _, terminated, truncated, _ = env.step(a)
                    if terminated or truncated:
                        env.reset()
                elapsed[b] += time.perf_counter() - t0
    finally:
        for env in envs.values():
            env.close()
    total = block * rounds
    return BenchResult({b: total / elapsed[b] for b in backends}, total, rounds)

