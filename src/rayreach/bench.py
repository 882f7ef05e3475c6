"""Environment throughput, measured side by side for both ray backends in one process."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

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



def step_breakdown(robot: str, scenario: str, calls: int = 2000, seed: int = 0) -> dict[str, float]:
    """Microseconds per call of each part of a step, timed in isolation on states visited by
    a random rollout: IK, ray geometry, both ray casts, joint reset + collision query."""
    env = ReachEnv(robot=robot, scenario=scenario)
    bullet = env.scene.caster("bullet")
    try:
        env.reset(seed=seed)
        env.action_space.seed(seed)
        states = []
        for _ in range(calls):
            _, _, terminated, truncated, _ = env.step(env.action_space.sample())
            states.append((env.q.copy(), env.frames.copy(), env.ee_pos.copy(), env.ee_rot.copy()))
            if terminated or truncated:
                env.reset()

        def timed(fn) -> float:
            t = time.perf_counter()
            for state in states:
                fn(*state)
            return (time.perf_counter() - t) / len(states) * 1e6

        ik_params = env.config.ik
        shift = np.array([env.spec_robot.ee_step, 0.0, 0.0])
        rays = [env.rays.world_rays(frames) for _, frames, _, _ in states]
        it = iter(rays)
        parts = {
            "ik": timed(lambda q, fr, p, r: env.kin.ik(p + shift, r, q, ik_params, start_frames=fr)),
            "ray_geometry": timed(lambda q, fr, p, r: env.rays.world_rays(fr)),
            "rays_numpy": timed(lambda *s: env.caster.cast(*next(it), env.rays.ray_range)),
        }
        it = iter(rays)
        parts["rays_bullet"] = timed(lambda *s: bullet.cast(*next(it), env.rays.ray_range))
        parts["joints_and_collision"] = timed(lambda q, *s: (env.scene.set_joints(q), env.scene.in_collision()))
    finally:
        env.close()
    return {k: round(v, 1) for k, v in parts.items()}
