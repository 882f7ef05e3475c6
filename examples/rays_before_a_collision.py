"""What the rays saw in the steps before a policy alone hit something, and what the
rays beyond the paper's would have seen on the same motion.

Runs a policy alone (deterministic) on validation worlds of one obstacle kind and, for every
episode that ends in a collision, counts over its last ``--window`` steps the rays that saw
anything: the paper's 129 by sensor (wrist, wraparound, tip), and the 24 tip-back and 32
slanted rays (``rayreach.sim.sensors.EXTRA_RAYS``) cast along the same motion whether or not
the policy observes them. A policy that decides every few control steps has its action held
in between, as in training. A plate just over the goal (``goal_cover``) lies edge-on to the
paper's rays; the plot shows how few of them see it before the tool does.

    python examples/rays_before_a_collision.py --model ur5 --kind goal_cover --episodes 10 --out rays.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: the figure only goes to a file
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from rayreach.env.reach import ReachEnv  # noqa: E402
from rayreach.learning.policy import load_policy  # noqa: E402
from rayreach.planners.drl import resolve_model  # noqa: E402
from rayreach.scenarios.random_world import KINDS, RandomWorldConfig  # noqa: E402
from rayreach.scenarios.splits import get_split  # noqa: E402
from rayreach.sim.sensors import EXTRA_RAYS, SENSOR_SLICES, RayModel  # noqa: E402

VALIDATION = get_split("validation").start
"""The validation split's first seed."""


def rays_before_collisions(model: str, kind: str, episodes: int, window: int) -> list[dict[str, np.ndarray]]:
    """Per collision episode: rays seeing anything at each of its last ``window`` steps, by sensor."""
    policy = load_policy(resolve_model(model))
    env = ReachEnv(robot=policy.robot, scenario="random", goal_tolerance=0.01,
                   random_world=RandomWorldConfig(n_obstacles=1, kinds=(kind,)), observation=policy.observation)
    extra = {name: RayModel(env.spec_robot, env.config.ray_range, layout(env.spec_robot))
             for name, _, layout in EXTRA_RAYS.values()}
    found = []
    try:
        for k in range(episodes):
            obs, _ = env.reset(seed=VALIDATION + k)
            seen: list[dict[str, int]] = []
            done, info, step = False, {}, 0
            while not done:
                if step % policy.decision_period == 0:  # held in between, as in training
                    action = policy.act(obs[None], deterministic=True)[0]
                obs, _, terminated, truncated, info = env.step(action)
                step += 1
                done = terminated or truncated
                fractions = env.perceive().fractions
                row = {name: int((fractions[block] < 1).sum()) for name, block in SENSOR_SLICES.items()}
                for name, rays in extra.items():
                    row[name] = int((env.caster.cast(*rays.world_rays(env.frames), env.config.ray_range) < 1).sum())
                seen.append(row)
            if info.get("collision"):
                last = seen[-window:]
                found.append({name: np.array([r[name] for r in last]) for name in last[0]})
    finally:
        env.close()
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="ur5", help="ur5 or kr16 (the shipped policy), or a model .zip")
    parser.add_argument("--kind", default="goal_cover", choices=KINDS, help="the one obstacle's kind")
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--window", type=int, default=30, help="steps before the collision")
    parser.add_argument("--out", required=True, type=Path)
    args = parser.parse_args()
    found = rays_before_collisions(args.model, args.kind, args.episodes, args.window)
    names = [*SENSOR_SLICES, *(name for name, _, _ in EXTRA_RAYS.values())]
    fig, ax = plt.subplots(figsize=(7, 4))
    for name, color in zip(names, ("#7f7f7f", "#1f5fd6", "#2b9a3e", "#d62728", "#9467bd")):
        for counts in found:
            ax.plot(np.arange(-len(counts[name]) + 1, 1), counts[name], color=color, alpha=0.15, lw=0.8)
        full = [c[name] for c in found if len(c[name]) == args.window]
        if full:  # the mean over collisions that had the whole window
            ax.plot(np.arange(-args.window + 1, 1), np.mean(full, axis=0), color=color, lw=2.2, label=f"{name} (mean)")
    ax.set_xlabel("steps before the collision")
    ax.set_ylabel("rays that see anything")
    ax.set_title(f"{len(found)} collisions of {args.episodes} {args.kind} worlds, policy alone")
    ax.grid(alpha=0.3)
    if found:
        ax.legend()
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    for name in names:
        most = [int(c[name].max()) for c in found]
        print(f"{name}: most rays seeing anything in the last {args.window} steps, per collision: {most}")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
