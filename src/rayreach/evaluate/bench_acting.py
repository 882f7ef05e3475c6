"""What each acting layer costs per step: the stack, the stack minus each layer and the policy
alone, on the same random worlds, one episode of each in turn in one process."""

from __future__ import annotations

from pathlib import Path

from tqdm import tqdm

from rayreach.acting import ActingEnv, ActingPolicy
from rayreach.env.episode import run_episode
from rayreach.env.reach import ReachEnv
from rayreach.learning.policy import load_policy
from rayreach.planners import DRL_PLANNERS, drl_acting
from rayreach.scenarios.splits import get_split

VARIANTS = {name: drl_acting(name) for name in DRL_PLANNERS}
"""The evaluation's DRL planners and their layers."""


def bench_acting(model: str | Path, episodes: int = 10, n_obstacles: int | None = None, split: str = "validation",
                 progress: bool = True) -> dict[str, dict[str, float]]:
    """Per variant: microseconds per step (choosing the action and stepping, the policy's
    forward pass included) and the ratio to the stack's, over the same ``episodes`` worlds
    of ``split``. Interleaved episode by episode, so a change in the machine's speed hits
    every variant alike."""
    policy = load_policy(model)
    base = ReachEnv(robot=policy.robot, scenario="random", observation=policy.observation)
    trained = policy.meta.get("state", {}).get("obstacles", {}).get("count", 0)
    base.set_n_obstacles(trained if n_obstacles is None else n_obstacles)
    envs = {name: ActingEnv(base, config) for name, config in VARIANTS.items()}
    agents = {name: ActingPolicy.acting(policy, config) for name, config in VARIANTS.items()}
    seconds, steps = dict.fromkeys(VARIANTS, 0.0), dict.fromkeys(VARIANTS, 0)
    first = get_split(split).start
    try:
        for episode in tqdm(range(episodes), desc="bench-acting", disable=not progress, leave=False):
            for name, env in envs.items():
                agents[name].reset(first + episode)
                run = run_episode(env, agents[name].act, first + episode)
                seconds[name] += run.compute_time
                steps[name] += run.steps
    finally:
        base.close()
    per_step = {name: 1e6 * seconds[name] / max(steps[name], 1) for name in VARIANTS}
    return {name: {"us_per_step": round(per_step[name], 1), "ratio": round(per_step[name] / per_step["drl"], 3),
                   "steps": steps[name]} for name in VARIANTS}
