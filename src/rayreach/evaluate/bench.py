"""Benchmarks: environment throughput (both ray backends side by side, or the single env
against the batched one), and the planners."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

import numpy as np

from rayreach.env.reach import ReachEnv
from rayreach.sim.scene import RAY_BACKENDS

if TYPE_CHECKING:
    from rayreach.planners.collision import CollisionChecker


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


RESETS_PER_ROUND = 20
"""Resets each env takes per round in ``bench_batched``'s timing of resets alone."""


def bench_batched(robot: str, scenario: str, n_worlds: int = 256, steps: int = 20000, rounds: int = 3,
                  seed: int = 0) -> dict:
    """World steps per second of one ``ReachEnv`` and of a ``BatchedReachEnv`` of ``n_worlds``
    worlds, each taking ``steps`` world steps (the batched env ``steps / n_worlds`` calls) of
    uniformly random actions, in ``rounds`` interleaved blocks; episodes reset as they end,
    resets included. Building the envs and their first reset (numba's compiled code is
    loaded then) are not timed. Also: the batched step's seconds per stage, per world step,
    and what a reset costs each env (``RESETS_PER_ROUND`` resets a round, interleaved)."""
    from rayreach.env.batched import BatchedReachEnv

    single = ReachEnv(robot=robot, scenario=scenario)
    batched = BatchedReachEnv(robot, n_worlds, scenario, seed=seed)
    rng = np.random.default_rng(seed)
    calls = max(1, steps // (n_worlds * rounds))
    block = calls * n_worlds
    elapsed = {"single": 0.0, "batched": 0.0}
    try:
        single.reset(seed=seed)
        batched.reset()
        batched.step(rng.uniform(-1, 1, (n_worlds, 6)).astype(np.float32))  # warm-up: first call of each kernel
        batched.stage_seconds = dict.fromkeys(batched.stage_seconds, 0.0)
        for _ in range(rounds):
            actions = rng.uniform(-1, 1, (block, 6)).astype(np.float32)
            t0 = time.perf_counter()
            for a in actions:
                _, _, terminated, truncated, _ = single.step(a)
                if terminated or truncated:
                    single.reset()
            elapsed["single"] += time.perf_counter() - t0
            t0 = time.perf_counter()
            for k in range(calls):
                batched.step(actions[k * n_worlds:(k + 1) * n_worlds])
            elapsed["batched"] += time.perf_counter() - t0
        resets = {"single": 0.0, "batched": 0.0}
        for r in range(rounds):  # random-world resets alone: what training's short episodes pay
            t0 = time.perf_counter()
            for _ in range(RESETS_PER_ROUND):
                single.reset()
            resets["single"] += time.perf_counter() - t0
            t0 = time.perf_counter()
            for i in range(RESETS_PER_ROUND):
                batched.reset_world((r * RESETS_PER_ROUND + i) % n_worlds)
            resets["batched"] += time.perf_counter() - t0
    finally:
        single.close()
        batched.close()
    total = block * rounds
    rates = {k: total / v for k, v in elapsed.items()}
    stages = {k: round(v / total * 1e6, 2) for k, v in batched.stage_seconds.items()}
    return {"robot": robot, "scenario": scenario, "n_worlds": n_worlds, "steps": total,
            "steps_per_s": {k: round(v, 1) for k, v in rates.items()},
            "speedup": round(rates["batched"] / rates["single"], 2), "us_per_world_step": stages,
            "ms_per_reset": {k: round(v / (rounds * RESETS_PER_ROUND) * 1e3, 2) for k, v in resets.items()}}



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


def checks_per_second(checker: "CollisionChecker", low: np.ndarray, high: np.ndarray, n: int = 5000,
                      seed: int = 0) -> float:
    """Configuration checks per second of the shared checker on uniform samples in a box."""
    samples = np.random.default_rng(seed).uniform(low, high, size=(n, len(low)))
    t0 = time.perf_counter()
    for q in samples:
        checker.valid(q)
    return n / (time.perf_counter() - t0)


def bench_planners(scenario: str, runs: int, planners: Sequence[str], time_limit: float = 30.0,
                   progress: bool = True) -> dict:
    """Every sampling planner on ``runs`` seeds of one scenario through the executor: median
    planning time over solved queries and end-effector path length over successful runs, success counts, and the
    checker's configuration checks per second (in the start-goal sampling box)."""
    from tqdm import tqdm

    from rayreach.evaluate.executor import Executor
    from rayreach.planners import make_planner
    from rayreach.planners.collision import sampling_box

    results: dict = {}
    with Executor(scenario) as ex:
        q_start = ex.reset(0)
        goals, _, _ = ex.goal_configurations(0)
        low, high = sampling_box(ex.checker, q_start, goals[-1] if goals else q_start, 1.0)
        cps = checks_per_second(ex.checker, low, high)
        bar = tqdm(total=runs * len(planners), desc=f"bench-planners {scenario}", disable=not progress, leave=False)
        for name in planners:
            planner = make_planner(name, ex.robot, time_limit=time_limit)
            records = []
            for seed in range(runs):
                records.append(ex.run(planner, seed))
                bar.update()
            solved = [r for r in records if r.plan_status == "solved"]
            succeeded = [r for r in records if r.success]
            results[name] = {
                "solved": len(solved),
                "success": sum(r.success for r in records),
                "runs": runs,
                "planning_time_median_s": float(np.median([r.planning_time for r in solved])) if solved else None,
                "path_length_median_m": float(np.median([r.path_length for r in succeeded])) if succeeded else None,
                "statuses": sorted({r.plan_status for r in records}),
            }
        bar.close()
    return {"scenario": scenario, "runs": runs, "time_limit_s": time_limit, "checks_per_s": round(cps, 1),
            "planners": results}
