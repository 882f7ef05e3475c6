"""Run a saved policy on a scenario and summarise what it did."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from rayreach.detour import Detour
from rayreach.env import OUTCOMES, ReachEnv, episode_outcome
from rayreach.policy import ActingPolicy, FinalApproach, load_policy
from rayreach.safety import ACTING_SAFETY, SafetyLayer
from rayreach.scenarios import RANDOM
from rayreach.scenarios.random_world import RandomWorldConfig, world_kinds

EVAL_SEED_OFFSET = 1_000_000
"""Random-world rollouts draw seeds from here on; training uses seeds below it."""


@dataclass
class RolloutSummary:
    episodes: int
    success_rate: float
    collision_rate: float
    path_length_mean: float
    """Mean end-effector path length of successful episodes, m (NaN if none)."""
    steps_mean: float
    successes: int
    collisions: int
    deterministic: bool
    final_approach: bool
    detour: bool
    resample: bool
    """Whether a held arm's repeated observation drew its action (``ActingPolicy``)."""
    safety: dict[str, float]
    outcomes: dict[str, int] = field(default_factory=dict)
    """Episodes per outcome: success, collision, out_of_bounds, timeout."""
    by_kind: dict[str, dict[str, int]] = field(default_factory=dict)
    """Random worlds: per obstacle kind (``random_world.KINDS``), the episodes whose world drew
    it and their outcomes; a world with two kinds counts for both."""
    per_episode: list[dict] = field(default_factory=list)

    def to_dict(self, with_episodes: bool = False) -> dict:
        data = asdict(self)
        if not with_episodes:
            data.pop("per_episode")
        return {k: (None if isinstance(v, float) and v != v else v) for k, v in data.items()}  # NaN -> null


def _count(records: list[dict]) -> dict[str, int]:
    return {o: sum(r["outcome"] == o for r in records) for o in OUTCOMES}


def rollout(
    model: str | Path,
    scenario: str,
    episodes: int = 10,
    deterministic: bool = True,
    goal_tolerance: float = 0.01,
    n_obstacles: int | None = None,
    seed: int = EVAL_SEED_OFFSET,
    progress: bool = True,
    final_approach: FinalApproach | None = FinalApproach(),
    safety: SafetyLayer = ACTING_SAFETY,
    resample: bool = True,
    detour: Detour | None = Detour(),
    start_clearance: float = 0.0,
) -> RolloutSummary:
    """``episodes`` episodes of the policy at ``goal_tolerance``. Random worlds use the
    final obstacle count of training unless ``n_obstacles`` is given, and keep the robot's
    start ``start_clearance`` from every obstacle (``RandomWorldConfig.start_clearance``).
    ``final_approach`` and ``detour`` None, ``SafetyLayer()`` and ``resample`` False measure
    the policy alone."""
    policy = load_policy(model)
    acting = ActingPolicy(policy, deterministic=deterministic, resample=resample)
    env = ReachEnv(robot=policy.robot, scenario=scenario, goal_tolerance=goal_tolerance,
                   safety=safety, final_approach=final_approach, detour=detour,
                   random_world=RandomWorldConfig(start_clearance=start_clearance))
    if scenario == RANDOM:
        trained = policy.meta.get("state", {}).get("obstacles", {}).get("count", 0)
        env.set_n_obstacles(trained if n_obstacles is None else n_obstacles)
    records = []
    try:
        for episode in tqdm(range(episodes), desc=f"rollout {scenario}", disable=not progress, leave=False):
            obs, info = env.reset(seed=seed + episode)
            acting.reset(seed + episode)
            path = [info["ee_position"]]
            done = False
            while not done:
                obs, _, terminated, truncated, info = env.step(acting.act(obs))
                path.append(info["ee_position"])
                done = terminated or truncated
            length = float(np.linalg.norm(np.diff(np.asarray(path), axis=0), axis=1).sum())
            records.append({"success": bool(info["is_success"]), "collision": bool(info["collision"]),
                            "out_of_bounds": bool(info["out_of_bounds"]), "outcome": episode_outcome(info),
                            "steps": len(path) - 1, "path_length": length,
                            "kinds": world_kinds(env.scenario) if scenario == RANDOM else []})
    finally:
        env.close()
    successes = sum(r["success"] for r in records)
    collisions = sum(r["collision"] for r in records)
    lengths = [r["path_length"] for r in records if r["success"]]
    return RolloutSummary(
        episodes=episodes,
        success_rate=successes / episodes,
        collision_rate=collisions / episodes,
        path_length_mean=float(np.mean(lengths)) if lengths else float("nan"),
        steps_mean=float(np.mean([r["steps"] for r in records])),
        successes=successes,
        collisions=collisions,
        deterministic=deterministic,
        final_approach=final_approach is not None,
        detour=detour is not None,
        resample=acting.draws_where_held,
        safety=asdict(safety),
        outcomes=_count(records),
        by_kind={kind: {"episodes": sum(kind in r["kinds"] for r in records),
                        **_count([r for r in records if kind in r["kinds"]])}
                 for kind in sorted({k for r in records for k in r["kinds"]})},
        per_episode=records,
    )
