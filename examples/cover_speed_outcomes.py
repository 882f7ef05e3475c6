"""How a policy alone fares under a goal cover, by how fast the cover moves.

A cover 4-7 cm over the goal leaves it at 5-20 cm/s (``rayreach.scenarios.random_world``):
the slower it goes, the longer the tool must wait before the goal is free. A policy that
waits does as well under a slow cover as under a fast one; one that dives at the goal
succeeds only when the cover has gone by in time, more often the faster it goes. Each
policy acts alone, deterministically, on the same validation worlds (all stepped at once);
every world with a cover counts once, in the bin of its slowest cover. It prints the
outcomes per bin and draws the success rate per bin, one line per policy.

    python examples/cover_speed_outcomes.py --model models/train-ur5-v4/model.zip \\
        --model runs/ablate-cover-speed-ur5/slow-covers/model.zip --episodes 500 --out speeds.png
"""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: the figure only goes to a file
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from rayreach.env.reach import OUTCOMES, ReachEnv  # noqa: E402
from rayreach.evaluate.rollout import rollout_batched  # noqa: E402
from rayreach.learning.policy import load_policy  # noqa: E402
from rayreach.planners.drl import resolve_model  # noqa: E402

BINS = np.linspace(0.05, 0.2, 5)
"""Edges of the speed bins, m/s: the suites' range in four."""


def slowest_covers(robot: str, seeds: list[int], n_obstacles: int) -> dict[int, float]:
    """The speed of the slowest goal cover, m/s, of each world (seed) that has one, drawn as
    ``rollout_batched`` draws it."""
    env = ReachEnv(robot=robot, scenario="random")
    env.set_n_obstacles(n_obstacles)
    speeds = {}
    try:
        for seed in seeds:
            env.reset(seed=seed)
            covers = [float(np.linalg.norm(o.velocity)) for o in env.scenario.obstacles
                      if (o.name or "").startswith("goal_cover")]
            if covers:
                speeds[seed] = min(covers)
    finally:
        env.close()
    return speeds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", action="append", default=None,
                        help="a policy bundle or a shipped robot's name, once per policy (default: ur5)")
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--obstacles", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("cover-speeds.png"))
    args = parser.parse_args()
    models = [resolve_model(m) for m in args.model or ["ur5"]]

    centres = (BINS[:-1] + BINS[1:]) / 2
    fig, ax = plt.subplots(figsize=(6.5, 4))
    speeds = None
    for model in models:
        summary = rollout_batched(model, episodes=args.episodes, n_obstacles=args.obstacles, split="validation")
        if speeds is None:
            speeds = slowest_covers(load_policy(model).robot, [r["seed"] for r in summary.per_episode],
                                    args.obstacles)
        outcome = {r["seed"]: r["outcome"] for r in summary.per_episode}
        print(f"{model}: alone {summary.success_rate:.1%} success, {summary.collision_rate:.1%} collisions; "
              f"under a cover {sum(outcome[s] == 'success' for s in speeds)} of {len(speeds)}")
        rates = []
        for low, high in zip(BINS[:-1], BINS[1:]):
            inside = [outcome[s] for s, v in speeds.items() if low <= v < high or (high == BINS[-1] and v == high)]
            counts = Counter(inside)
            print(f"  cover {low:.3f}-{high:.3f} m/s: {len(inside)} worlds, "
                  + ", ".join(f"{o} {counts[o]}" for o in OUTCOMES))
            rates.append(counts["success"] / len(inside) if inside else np.nan)
        ax.plot(centres, rates, "o-", label="/".join(Path(model).parts[-2:]))
    ax.set_xlabel("speed of the slowest goal cover, m/s (bin centres)")
    ax.set_ylabel("success alone")
    ax.set_ylim(0, 1)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(f"Worlds with a goal cover, first {args.episodes} validation worlds, {args.obstacles} obstacles",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
