"""Training recipes compared on one fixed task at equal wall time.

``rayreach compare-recipes --robot ur5 --minutes 15 --out runs/compare`` trains each recipe in
``COMPARED`` (both of ``rayreach.learning.train.RECIPES``) from scratch on the same task
(random worlds of one obstacle, a 0.1 m goal, both curricula held), for the same wall time
one after the other, then runs each final policy alone, deterministically, on validation
worlds of that task. It writes ``curves.png`` (success over wall time, both recipes) and
``summary.json``. A run that was stopped resumes where it stood: finished recipes are kept,
an interrupted one continues from its checkpoint with the wall time it has left.
"""

from __future__ import annotations

import csv
import json
import os
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from stable_baselines3.common.callbacks import BaseCallback

from rayreach.learning.bundles import read_bundle_meta
from rayreach.learning.curriculum import GoalSizeParams, ObstacleParams
from rayreach.learning.train import CHECKPOINT, CURVE, MODEL, RECIPES, TrainConfig, recipe, train

GOAL = 0.1
"""The task's goal radius, m."""
OBSTACLES = 1
"""The task's obstacles per world."""
COMPARED = ("baseline", "default")


def fixed_task(config: TrainConfig) -> TrainConfig:
    """``config`` on the fixed task: the goal-size and obstacle curricula held at their values."""
    return replace(config, timesteps=10**12, true_goal_share=0.0,
                   goal=GoalSizeParams(rho=GOAL, rho_max=GOAL, rho_min=GOAL),
                   obstacles=ObstacleParams(start=OBSTACLES, minimum=OBSTACLES, maximum=OBSTACLES))


class WallClock(BaseCallback):
    """Ends ``learn()`` at the first step after ``seconds`` of wall time."""

    def __init__(self, seconds: float) -> None:
        super().__init__()
        self.seconds = seconds
        self.start = 0.0

    def _on_training_start(self) -> None:
        self.start = time.monotonic()

    def _on_step(self) -> bool:
        return time.monotonic() - self.start < self.seconds


def train_for(config: TrainConfig, seconds: float, out: Path) -> Path:
    """``out``'s model after ``seconds`` of training in all (a checkpoint's wall time counts)."""
    if (out / MODEL).exists():
        return out / MODEL
    resume = (out / CHECKPOINT).exists()
    spent = float(read_bundle_meta(out / CHECKPOINT)[0].get("wall_time_s", 0.0)) if resume else 0.0
    return train(config, out, resume=resume, callbacks=[WallClock(max(0.0, seconds - spent))])


def curve(path: Path) -> dict[str, list[float]]:
    with path.open() as handle:
        rows = list(csv.DictReader(handle))
    return {key: [float(r[key]) for r in rows]
            for key in ("wall_time", "timesteps", "success_rate", "collision_rate")}


def compare_recipes(robot: str, minutes: float, out: str | Path, episodes: int = 200,
                    progress: bool = True) -> dict[str, Any]:
    """Train every recipe in ``COMPARED`` for ``minutes`` on the fixed task, check each on
    ``episodes`` validation worlds; the summary, with the plot written beside it."""
    from rayreach.acting import ActingConfig
    from rayreach.evaluate.rollout import rollout

    if minutes <= 0:
        raise ValueError(f"minutes must be positive, got {minutes}")
    out = Path(out)
    summary: dict[str, Any] = {"robot": robot, "minutes": minutes, "goal_m": GOAL, "obstacles": OBSTACLES,
                               "episodes": episodes, "split": "validation", "cores": os.cpu_count(), "recipes": {}}
    for name in COMPARED:
        model = train_for(fixed_task(recipe(name, robot=robot)), minutes * 60.0, out / name)
        checked = rollout(str(model), "random", episodes=episodes, goal_tolerance=GOAL, n_obstacles=OBSTACLES,
                          acting=ActingConfig.off(), split="validation", progress=progress)
        meta, _ = read_bundle_meta(model)
        summary["recipes"][name] = {"timesteps": meta["timesteps"], "wall_time_s": meta["wall_time_s"],
                                    "validation": {k: checked.to_dict()[k] for k in
                                                   ("success_rate", "collision_rate", "outcomes")},
                                    "curve": curve(out / name / CURVE)}
    plot_curves(summary, out / "curves.png")
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return summary


def plot_curves(summary: dict[str, Any], path: Path) -> Path:
    """Training success (last 200 episodes) over wall time and over samples, per recipe."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (by_time, by_samples) = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for (name, data), color in zip(summary["recipes"].items(), ("#7f7f7f", "#1f5fd6")):
        c, final = data["curve"], data["validation"]["success_rate"]
        label = f"{name}: validation {final:.0%} alone"
        by_time.plot([t / 60 for t in c["wall_time"]], c["success_rate"], color=color, label=label)
        by_samples.plot([s / 1e6 for s in c["timesteps"]], c["success_rate"], color=color, label=label)
    by_time.set_xlabel(f"wall time (min, {summary['cores']} cores)")
    by_samples.set_xlabel("environment steps (millions)")
    by_time.set_ylabel("training success, last 200 episodes")
    for ax in (by_time, by_samples):
        ax.grid(alpha=0.3)
        ax.set_ylim(-0.02, 1.02)
    by_time.legend(loc="lower right", fontsize=8)
    fig.suptitle(f"{summary['robot'].upper()}: recipes on one fixed task ({summary['obstacles']} obstacle, "
                 f"{summary['goal_m']} m goal), {summary['minutes']:g} min each")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


__all__ = ["COMPARED", "RECIPES", "compare_recipes", "fixed_task"]
