"""Run a saved policy on a scenario and summarise what it did."""

from __future__ import annotations

from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from rayreach.acting import ActingConfig, ActingEnv, ActingPolicy
from rayreach.env.reach import OUTCOMES, ReachEnv
from rayreach.env.episode import run_episode, share
from rayreach.learning.policy import load_policy
from rayreach.scenarios import RANDOM, WORLD_SUITES
from rayreach.scenarios.splits import get_split
from rayreach.scenarios.random_world import RandomWorldConfig
from rayreach.scenarios.suites import suite_kinds

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
    acting_layers: list[str]
    """The acting layers that were on (``rayreach.acting.LAYERS``)."""
    acting_share: dict[str, float]
    """The share of all steps by what chose the executed motion (``info["acting"]["source"]``)."""
    safety: dict[str, float]
    split: str | None = None
    """Drawn worlds (random, broad): the seed split they were drawn from."""
    outcomes: dict[str, int] = field(default_factory=dict)
    """Episodes per outcome: success, collision, out_of_bounds, timeout."""
    by_kind: dict[str, dict[str, int]] = field(default_factory=dict)
    """Random worlds: per obstacle kind (``random_world.KINDS``), the episodes whose world drew
    it and their outcomes; a world with two kinds counts for both."""
    held_by: dict[str, float] = field(default_factory=dict)
    """The share of all steps in which the arm was held, by what held it
    (``rayreach.acting.pipeline.held_by``): where the layers cost a policy its time."""
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
    seed: int | None = None,
    progress: bool = True,
    acting: ActingConfig = ActingConfig(),
    start_clearance: float = 0.0,
    split: str = "validation",
) -> RolloutSummary:
    """``episodes`` episodes of the policy at ``goal_tolerance``, acting through ``acting``
    (``ActingConfig.off()``: the policy alone). Drawn worlds (``WORLD_SUITES``) come from seed ``split`` (from
    ``seed`` on, which must lie in it; default: the split's first), use the final obstacle
    count of training unless ``n_obstacles`` is given, and keep the robot's start
    ``start_clearance`` from every obstacle (``RandomWorldConfig.start_clearance``)."""
    drawn = scenario in WORLD_SUITES
    first = _first_seed(split, seed, episodes, drawn=drawn)
    policy = load_policy(model)
    agent = ActingPolicy.acting(policy, acting, deterministic)
    base = ReachEnv(robot=policy.robot, scenario=scenario, goal_tolerance=goal_tolerance,
                    random_world=RandomWorldConfig(start_clearance=start_clearance), observation=policy.observation)
    env = ActingEnv(base, acting)
    if drawn:
        base.set_n_obstacles(_trained_obstacles(policy) if n_obstacles is None else n_obstacles)
    records, sources, held = [], Counter(), Counter()
    try:
        for episode in tqdm(range(episodes), desc=f"rollout {scenario}", disable=not progress, leave=False):
            agent.reset(first + episode)
            run = run_episode(env, agent.act, first + episode)
            sources.update(run.sources)
            held.update(run.held_by)
            info = run.info
            records.append({"success": bool(info["is_success"]), "collision": bool(info["collision"]),
                            "out_of_bounds": bool(info["out_of_bounds"]), "outcome": run.outcome,
                            "steps": run.steps, "path_length": run.path_length, "seed": first + episode,
                            "acting_share": run.acting_share,
                            "kinds": suite_kinds(scenario, base.scenario) if drawn else []})
    finally:
        env.close()
    return _summary(records, deterministic, acting, sources, split, drawn, held)


def _first_seed(split: str, seed: int | None, episodes: int, drawn: bool = True) -> int:
    """The first world's seed (default: the split's first); where worlds are ``drawn``, the
    ``episodes`` seeds from it must lie in ``split``."""
    chosen = get_split(split)
    first = chosen.start if seed is None else int(seed)
    if drawn and not (first in chosen and first + episodes - 1 in chosen):
        raise ValueError(f"seeds {first}..{first + episodes - 1} leave the {split} split "
                         f"({chosen.start}..{chosen.stop - 1})")
    return first


def _trained_obstacles(policy) -> int:
    """The obstacle count the policy's training ended at."""
    return policy.meta.get("state", {}).get("obstacles", {}).get("count", 0)


def _summary(records: list[dict], deterministic: bool, acting: ActingConfig, sources: Counter, split: str,
             drawn: bool, held: Counter | None = None) -> RolloutSummary:
    episodes = len(records)
    steps = sum(sources.values())
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
        acting_layers=list(acting.layers),
        acting_share=share(sources),
        held_by={k: n / steps for k, n in sorted((held or {}).items())} if steps else {},
        safety=asdict(acting.safety),
        split=split if drawn else None,
        outcomes=_count(records),
        by_kind={kind: {"episodes": sum(kind in r["kinds"] for r in records),
                        **_count([r for r in records if kind in r["kinds"]])}
                 for kind in sorted({k for r in records for k in r["kinds"]})},
        per_episode=records,
    )


def rollout_batched(
    model: str | Path,
    episodes: int = 200,
    goal_tolerance: float = 0.01,
    n_obstacles: int | None = None,
    seed: int | None = None,
    start_clearance: float = 0.0,
    split: str = "validation",
    suite: str = RANDOM,
) -> RolloutSummary:
    """``rollout`` of the policy alone, deterministic, on drawn worlds, all ``episodes`` worlds
    stepped at once in one ``BatchedReachEnv`` (world ``k`` is the world of seed
    ``first + k``, as ``rollout`` draws it): one forward pass per decision for all worlds."""
    from rayreach.env.batched import BatchedReachEnv
    from rayreach.env.reach import EnvConfig, episode_outcome

    first = _first_seed(split, seed, episodes)
    policy = load_policy(model)
    if n_obstacles is None:
        n_obstacles = _trained_obstacles(policy)
    config = EnvConfig(goal_tolerance=goal_tolerance, observation=policy.observation,
                       random_world=RandomWorldConfig(n_obstacles=n_obstacles, start_clearance=start_clearance))
    env = BatchedReachEnv(policy.robot, episodes, suite, config=config, seed=first)
    records: list[dict | None] = [None] * episodes
    try:
        obs = env.reset()
        kinds = [suite_kinds(suite, s) for s in env.scenarios]
        lengths = np.zeros(episodes)
        last = env.ee_pos.copy()
        step = 0
        while any(r is None for r in records):
            if step % policy.decision_period == 0:  # every world's first episode starts on step 0
                action = policy.act(obs, deterministic=True)
            obs, _, dones, infos = env.step(action)
            step += 1
            ended = np.asarray(dones, dtype=bool)
            now = np.array([info["ee_position"] if ended[i] else env.ee_pos[i] for i, info in enumerate(infos)])
            lengths += np.linalg.norm(now - last, axis=1)
            last = env.ee_pos.copy()
            for i in np.flatnonzero(ended):
                if records[i] is None:
                    info = infos[i]
                    records[i] = {"success": bool(info["is_success"]), "collision": bool(info["collision"]),
                                  "out_of_bounds": bool(info["out_of_bounds"]), "outcome": episode_outcome(info),
                                  "steps": int(round(info["time"] / config.control_period)),
                                  "path_length": float(lengths[i]), "seed": first + int(i),
                                  "acting_share": {"policy": 1.0}, "kinds": kinds[i]}
    finally:
        env.close()
    return _summary([r for r in records if r is not None], True, ActingConfig.off(), Counter(policy=1), split, True)
