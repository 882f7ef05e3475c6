"""Which link of the robot touches the obstacle when a policy alone collides.

Runs a policy alone (deterministic) on validation worlds of its training suite (random or broad)
and, for every episode that ends in a collision, asks PyBullet's contacts which links
penetrate (``Scene.colliding_links``). Rays along the upper arm and forearm would help only
if those links are what hits; the bar chart says whether they are, and the printout says it
for each kind of the goal's scene (broad worlds) or of the first obstacle (random worlds).

    python examples/what_the_arm_hits.py --model models/train-ur5-v3/model.zip --obstacles 2 --episodes 200 --out hits.png
"""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: the figure only goes to a file
import matplotlib.pyplot as plt  # noqa: E402

from rayreach.env.decisions import HeldAction  # noqa: E402
from rayreach.env.reach import ReachEnv  # noqa: E402
from rayreach.learning.policy import load_policy  # noqa: E402
from rayreach.planners.drl import resolve_model  # noqa: E402
from rayreach.scenarios.random_world import RandomWorldConfig  # noqa: E402
from rayreach.scenarios.splits import get_split  # noqa: E402
from rayreach.scenarios.suites import suite_kinds  # noqa: E402

VALIDATION = get_split("validation").start
"""The validation split's first seed."""


def links_hit(model: str, obstacles: int, episodes: int) -> tuple[Counter, int, dict[str, Counter]]:
    """Per link name, the collision episodes in which it penetrated an obstacle; how many
    episodes collided; and per kind of the world's first element, its episodes, collisions and
    links in contact."""
    policy = load_policy(resolve_model(model))
    env = ReachEnv(robot=policy.robot, scenario=policy.suite, goal_tolerance=0.01,
                   random_world=RandomWorldConfig(), observation=policy.observation)
    env.set_n_obstacles(obstacles)  # as ``rayreach rollout --obstacles`` sets it
    stepper = HeldAction(env, policy.decision_period)  # each action held as in training
    hits, collided, by_kind = Counter(), 0, {}
    try:
        for k in range(episodes):
            obs, _ = env.reset(seed=VALIDATION + k)
            kind = by_kind.setdefault((suite_kinds(policy.suite, env.scenario) or ["empty"])[0], Counter())
            kind["episodes"] += 1
            done, info = False, {}
            while not done:
                obs, _, terminated, truncated, info = stepper.step(policy.act(obs[None], deterministic=True)[0])
                done = terminated or truncated
            if info.get("collision"):
                collided += 1
                links = env.scene.colliding_links()
                hits.update(links)
                kind.update(["collisions", *links])
    finally:
        env.close()
    return hits, collided, by_kind


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="ur5", help="ur5 or kr16 (the shipped policy), or a model .zip")
    parser.add_argument("--obstacles", type=int, default=2, help="obstacles per world (elements in broad worlds)")
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--out", required=True, type=Path)
    args = parser.parse_args()
    hits, collided, by_kind = links_hit(args.model, args.obstacles, args.episodes)
    names = [name for name, _ in hits.most_common()]
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.bar(names or ["(none)"], [hits[n] for n in names] or [0], color="#1f5fd6")
    ax.set_ylabel("collision episodes")
    ax.set_title(f"links in contact: {collided} collisions of {args.episodes} worlds, policy alone")
    ax.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"{collided} of {args.episodes} episodes collided; links in contact: {dict(hits.most_common())}")
    for kind, counts in sorted(by_kind.items()):
        print(f"  {kind}: {dict(counts.most_common())}")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
