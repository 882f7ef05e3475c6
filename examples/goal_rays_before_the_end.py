"""Whether the straight way from the tool to the goal was blocked as a policy's episodes ended.

The policy acts alone, deterministically, on validation worlds, all stepped at once. Beside
it, every control step, the three goal rays (``rayreach.sim.goal_rays``: from the tip, the
tool's middle and the flange, towards the goal) are cast, whether or not the policy reads
them. For worlds with a goal cover and for the others, by outcome, it prints how many
episodes had a goal ray blocked in their last 40 control steps, and the share of all their
steps in which the tip's ray was blocked; the figure draws the first as bars. A collision
that comes with the way blocked is one the goal rays could have warned of.

    python examples/goal_rays_before_the_end.py --model models/train-ur5-v4/model.zip --episodes 300 --out ends.png
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: the figure only goes to a file
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from rayreach.env.batched import BatchedReachEnv  # noqa: E402
from rayreach.env.reach import EnvConfig, episode_outcome  # noqa: E402
from rayreach.learning.policy import load_policy  # noqa: E402
from rayreach.planners.drl import resolve_model  # noqa: E402
from rayreach.scenarios.random_world import RandomWorldConfig  # noqa: E402
from rayreach.scenarios.splits import get_split  # noqa: E402
from rayreach.scenarios.suites import suite_kinds  # noqa: E402

VALIDATION = get_split("validation").start
"""The validation split's first seed."""
LAST = 40
"""Control steps before the end that count as its approach (10 decisions of 4)."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="ur5", help="ur5 or kr16 (the shipped policy), or a model .zip")
    parser.add_argument("--episodes", type=int, default=20, help="validation worlds, from seed 1,000,000")
    parser.add_argument("--obstacles", type=int, default=2)
    parser.add_argument("--out", default="goal_rays.png")
    args = parser.parse_args()

    policy = load_policy(resolve_model(args.model))
    config = EnvConfig(goal_tolerance=0.01, observation=policy.observation,
                       random_world=RandomWorldConfig(n_obstacles=args.obstacles))
    env = BatchedReachEnv(policy.robot, args.episodes, "random", config=config, seed=VALIDATION)
    every = np.arange(args.episodes)
    seen: list[list[np.ndarray]] = [[] for _ in every]
    outcome: list[str | None] = [None] * args.episodes
    try:
        obs = env.reset()
        covered = ["goal_cover" in suite_kinds("random", s) for s in env.scenarios]
        step = 0
        while any(o is None for o in outcome):
            if step % policy.decision_period == 0:
                action = policy.act(obs, deterministic=True)
            clear = env.goal_clear(every)
            for i in every:
                if outcome[i] is None:
                    seen[i].append(clear[i])
            obs, _, dones, infos = env.step(action)
            step += 1
            for i in np.flatnonzero(dones):
                if outcome[i] is None:
                    outcome[i] = episode_outcome(infos[i])
    finally:
        env.close()

    groups: dict[tuple[bool, str], list[tuple[bool, float]]] = defaultdict(list)
    for i in every:
        history = np.array(seen[i])
        groups[(covered[i], outcome[i])].append((bool((history[-LAST:] < 1).any()), float((history[:, 0] < 1).mean())))
    print(f"{'worlds':<12} {'outcome':<14} {'episodes':>8} {'blocked at the end':>19} {'tip ray blocked':>16}")
    labels, totals, blocked = [], [], []
    for (cover, end), rows in sorted(groups.items()):
        ends = sum(b for b, _ in rows)
        print(f"{'goal cover' if cover else 'other':<12} {end:<14} {len(rows):>8} {ends:>19} "
              f"{np.mean([s for _, s in rows]):>15.0%}")
        labels.append(f"{'cover' if cover else 'other'}\n{end}")
        totals.append(len(rows))
        blocked.append(ends)

    fig, ax = plt.subplots(figsize=(8, 4))
    x = np.arange(len(labels))
    ax.bar(x, totals, color="0.8", label="episodes")
    ax.bar(x, blocked, color="tab:red", label=f"a goal ray blocked in the last {LAST} steps")
    ax.set_xticks(x, labels, fontsize=8)
    ax.set_ylabel("episodes")
    ax.set_title(f"{Path(str(args.model)).name}: the way to the goal as episodes ended")
    ax.legend()
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
