"""Training recipes, and one departure at a time from them, compared on one fixed task at
equal wall time.

``rayreach compare-recipes --robot ur5 --minutes 15 --out runs/compare`` trains each variant
(``VARIANTS``; by default ``COMPARED``, the baseline and default recipes) from scratch on the
same task (random worlds of ``--obstacles``, a ``--goal`` radius, both curricula held), for
the same wall time, then runs each final policy alone, deterministically, on validation
worlds of that task. ``--jobs N`` trains N variants at once, each on its share of the cores,
so that whatever else loads the machine loads them alike. It writes ``curves.png`` (success
over wall time and over samples) and ``summary.json``. A run that was stopped resumes where
it stood: finished variants are kept, an interrupted one continues from its checkpoint with
the wall time it has left.
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

from rayreach.env.observation import ObservationConfig
from rayreach.learning.bundles import read_bundle_meta
from rayreach.learning.curriculum import GoalSizeParams, ObstacleParams
from rayreach.learning.train import CHECKPOINT, CURVE, MODEL, RECIPES, TrainConfig, recipe, train

GOAL = 0.1
"""The task's goal radius, m (default)."""
OBSTACLES = 1
"""The task's obstacles per world (default)."""
COMPARED = ("baseline", "default")
VARIANTS: dict[str, tuple[str, dict[str, Any]]] = {
    "baseline": ("baseline", {}),
    "default": ("default", {}),
    "paper": ("paper", {}),
    "paper-observation": ("default", {"observation": ObservationConfig()}),
    "no-scans": ("default", {"observation": {"scans": 0}}),
    "long-scans": ("default", {"observation": {"scans": 4, "scan_stride": 24}}),
    "sightings": ("default", {"observation": {"sightings": 12}}),
    "no-workspace": ("default", {"observation": {"workspace": False}}),
    "entropy": ("default", {"ent_coef": 0.005}),
    "around-obstacles": ("default", {"progress_around_obstacles": True}),
    "proximity": ("default", {"proximity_weight": -0.1}),
    "gamma-0.995": ("default", {"gamma": 0.995}),
    "gamma-0.998": ("default", {"gamma": 0.998}),
    "tip-back": ("default", {"observation": {"tip_back": True}}),
    "no-tip-back": ("default", {"observation": {"tip_back": False}}),
    "collision-20": ("default", {"collision_weight": -20.0}),
    "collision-40": ("default", {"collision_weight": -40.0}),
    "more-covers": ("default", {"extra_kinds": ("goal_cover", "goal_cover")}),
    "slow-covers": ("default", {"cover_speed": (0.03, 0.08)}),
    "separate-features": ("default", {"share_features": False}),
    "wide": ("default", {"features": (512, 512)}),
    "decide-1": ("default", {"decision_period": 1}),
    "decide-2": ("default", {"decision_period": 2}),
    "decide-8": ("default", {"decision_period": 8}),
    "slanted": ("default", {"observation": {"slanted": True}}),
    "slanted-no-tip-back": ("default", {"observation": {"tip_back": False, "slanted": True}}),
    "goal-sight": ("default", {"observation": {"goal_sight": True}}),
}
"""What can be compared: a recipe, or a recipe with one change (its ablation). An
``observation`` given as a dict names the fields that change in the robot's own observation
under that recipe (the KR16's default has no tip-back rays, the UR5's has), so that a
variant adds its one change to each robot's default and nothing else."""


def variant(name: str, robot: str) -> TrainConfig:
    if name not in VARIANTS:
        raise ValueError(f"unknown variant {name!r}; choose from {', '.join(VARIANTS)}")
    base, changes = VARIANTS[name]
    config = recipe(base, robot=robot)
    if isinstance(changes.get("observation"), dict):
        changes = {**changes, "observation": replace(config.observation, **changes["observation"])}
    return replace(config, **changes)


def fixed_task(config: TrainConfig, goal: float = GOAL, obstacles: int = OBSTACLES) -> TrainConfig:
    """``config`` on the fixed task: the goal-size and obstacle curricula held at their values,
    no validations (each variant's wall time goes to training)."""
    return replace(config, timesteps=10**12, true_goal_share=0.0, validate_every=0, starts=1,
                   goal=GoalSizeParams(rho=goal, rho_max=goal, rho_min=goal),
                   obstacles=ObstacleParams(start=obstacles, minimum=obstacles, maximum=obstacles))


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


def _train_job(job: tuple[TrainConfig, float, Path]) -> Path:
    config, seconds, out = job
    return train_for(config, seconds, out)


def compare_recipes(robot: str, minutes: float, out: str | Path, episodes: int = 200,
                    progress: bool = True, variants: tuple[str, ...] = COMPARED, goal: float = GOAL,
                    obstacles: int = OBSTACLES, jobs: int = 1) -> dict[str, Any]:
    """Train every one of ``variants`` for ``minutes`` on the fixed task, ``jobs`` at a time,
    check each on ``episodes`` validation worlds; the summary, with the plot written beside it."""
    import multiprocessing as mp

    from rayreach.acting import ActingConfig
    from rayreach.evaluate.rollout import rollout

    if minutes <= 0:
        raise ValueError(f"minutes must be positive, got {minutes}")
    if jobs < 1:
        raise ValueError(f"jobs must be >= 1, got {jobs}")
    out = Path(out)
    cores = os.cpu_count() or 1
    share = max(1, cores // min(jobs, len(variants)))
    configs = {name: fixed_task(variant(name, robot), goal, obstacles) for name in variants}
    if jobs > 1:
        configs = {name: replace(c, workers=share) for name, c in configs.items()}
    work = [(configs[name], minutes * 60.0, out / name) for name in variants]
    if jobs > 1:
        with mp.get_context("spawn").Pool(min(jobs, len(work))) as pool:
            models = dict(zip(variants, pool.map(_train_job, work, chunksize=1)))
    else:
        models = {name: _train_job(job) for name, job in zip(variants, work)}
    summary: dict[str, Any] = {"robot": robot, "minutes": minutes, "goal_m": goal, "obstacles": obstacles,
                               "episodes": episodes, "split": "validation", "cores": cores, "jobs": jobs,
                               "recipes": {}}
    for name in variants:
        model = models[name]
        checked = rollout(str(model), "random", episodes=episodes, goal_tolerance=goal, n_obstacles=obstacles,
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
    colors = ("#7f7f7f", "#1f5fd6", "#d62728", "#2b9a3e", "#ff7f0e", "#9467bd", "#8c564b")
    for (name, data), color in zip(summary["recipes"].items(), colors):
        c, final = data["curve"], data["validation"]["success_rate"]
        label = f"{name}: validation {final:.0%} alone"
        by_time.plot([t / 60 for t in c["wall_time"]], c["success_rate"], color=color, label=label)
        by_samples.plot([s / 1e6 for s in c["timesteps"]], c["success_rate"], color=color, label=label)
    jobs = summary.get("jobs", 1)
    by_time.set_xlabel(f"wall time (min, {summary['cores']} cores" + (f", {jobs} runs at once)" if jobs > 1 else ")"))
    by_samples.set_xlabel("samples: the policy's decisions (millions)")
    by_time.set_ylabel("training success, last 200 episodes")
    for ax in (by_time, by_samples):
        ax.grid(alpha=0.3)
        ax.set_ylim(-0.02, 1.02)
    by_time.legend(loc="lower right", fontsize=8)
    fig.suptitle(f"{summary['robot'].upper()}: one fixed task ({summary['obstacles']} obstacle(s), "
                 f"{summary['goal_m']} m goal), {summary['minutes']:g} min each")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


__all__ = ["COMPARED", "RECIPES", "VARIANTS", "compare_recipes", "fixed_task", "variant"]
