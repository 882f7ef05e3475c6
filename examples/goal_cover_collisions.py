"""How a policy alone meets a goal under a moving cover: when, from where, how fast.

A ``goal_cover`` world holds one flat plate 4-7 cm over the goal, moving away at 5-20 cm/s;
the tool cannot reach the goal before the plate has gone by. For each validation world this
prints the outcome, the time it ended, the time the plate's trailing edge needs to clear the
goal by 3 cm, the tool tip's height over the plate's centre plane at the end, where the tip
stood along the plate's motion (negative: behind its centre) and how far its whole motion
went along the plate's (+1: chasing it, -1: meeting it), and the links in contact; the
figure sets each world's end against the time its plate needed to clear the goal.

    python examples/goal_cover_collisions.py --model models/train-ur5-v4/model.zip --episodes 60 --out cover.png
"""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: the figure only goes to a file
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from rayreach.env.decisions import HeldAction  # noqa: E402
from rayreach.env.reach import OUTCOMES, ReachEnv, episode_outcome  # noqa: E402
from rayreach.learning.policy import load_policy  # noqa: E402
from rayreach.planners.drl import resolve_model  # noqa: E402
from rayreach.scenarios.random_world import RandomWorldConfig  # noqa: E402
from rayreach.scenarios.splits import get_split  # noqa: E402

VALIDATION = get_split("validation").start
"""The validation split's first seed."""
CLEARANCE = 0.03
"""How far past the goal the plate's trailing edge must be before the tool fits, m."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="ur5", help="ur5 or kr16 (the shipped policy), or a model .zip")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--out", required=True, type=Path)
    args = parser.parse_args()
    policy = load_policy(resolve_model(args.model))
    env = ReachEnv(robot=policy.robot, scenario="random", goal_tolerance=0.01, observation=policy.observation,
                   random_world=RandomWorldConfig(n_obstacles=1, kinds=("goal_cover",)))
    stepper = HeldAction(env, policy.decision_period)  # each action held as in training
    outcomes: Counter = Counter()
    ends: dict[str, list[tuple[float, float]]] = {name: [] for name in OUTCOMES}
    print("world outcome    t (s)  clear (s)  tip over plate (m)  tip along motion (m)  approach  contact")
    try:
        for k in range(args.episodes):
            obs, _ = stepper.reset(seed=VALIDATION + k)
            plate = next(o for o in env.scenario.obstacles if o.name.startswith("goal_cover"))
            velocity = np.array(plate.velocity)
            heading = velocity[:2] / np.linalg.norm(velocity[:2])
            start = env.ee_pos.copy()
            done, info = False, {}
            while not done:
                obs, _, terminated, truncated, info = stepper.step(policy.act(obs[None], deterministic=True)[0])
                done = terminated or truncated
            outcome = episode_outcome(info)
            outcomes[outcome] += 1
            tip = env.ee_pos - np.array(plate.position_at(info["time"]))
            motion = (env.ee_pos - start)[:2]
            clear = (plate.half_extents[0] + CLEARANCE) / np.linalg.norm(velocity)
            ends[outcome].append((clear, info["time"]))
            contact = ",".join(env.scene.colliding_links()) if info["collision"] else ""
            print(f"{k:5d} {outcome:10s} {info['time']:5.2f} {clear:9.2f} {tip[2]:+18.3f} {tip[:2] @ heading:+21.3f}"
                  f" {motion @ heading / (np.linalg.norm(motion) + 1e-9):+9.2f}  {contact}")
    finally:
        env.close()
    print(dict(outcomes))
    fig, ax = plt.subplots(figsize=(5.5, 4.5))
    for name, color in zip(OUTCOMES, ("#2b9a3e", "#d62728", "#ff7f0e", "#7f7f7f")):
        if ends[name]:
            ax.scatter(*np.array(ends[name]).T, s=18, color=color, label=f"{name} ({len(ends[name])})")
    top = max(t for points in ends.values() for pair in points for t in pair)
    ax.plot([0, top], [0, top], color="black", lw=0.8, ls="--")
    ax.set_xlabel("time the plate needs to clear the goal, s")
    ax.set_ylabel("time the episode ended, s")
    ax.set_title(f"{args.episodes} goal_cover worlds, policy alone")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
