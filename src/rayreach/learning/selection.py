"""Choosing a run's best checkpoint on validation worlds while it trains.

A policy's success alone on fresh worlds does not rise steadily with training: the KR16's
default run gained two points between 40 and 50 M decisions, and its rate with the acting
stack was higher at 23 M than at 40 M (docs/training.md). So every ``validate_every``
decisions the run plays its checkpoint alone, deterministic, at the true 1 cm goal on
``validate_worlds`` validation worlds of the robot's task (``RobotSpec.task_obstacles``),
writes the figures to ``validation.csv`` and keeps the best checkpoint so far as
``best.zip``: what ``rayreach export`` ships from a run directory. The worlds start at
``SELECTION_SEED``, apart from the validation split's first worlds, which the docs' tuning
figures use, so a figure quoted there is not the figure a checkpoint was chosen on.
"""

from __future__ import annotations

import csv
import shutil
from pathlib import Path
from typing import Any

VALIDATION_CSV = "validation.csv"
BEST = "best.zip"
SELECTION_SEED = 2_000_000
"""First validation seed of the worlds a run chooses its checkpoint on."""
GOAL_TOLERANCE = 0.01
"""The true goal size: a checkpoint is judged where the policy is used."""


def score(success_rate: float, collision_rate: float) -> float:
    """What a checkpoint is ranked by: success less collisions (a collision costs a
    robot more than a timeout does, and the targets bound both)."""
    return success_rate - collision_rate


def validate(checkpoint: Path, robot: str, suite: str, worlds: int) -> dict[str, Any]:
    """The checkpoint alone on the selection worlds: its rates and score."""
    from rayreach.evaluate.rollout import rollout_batched
    from rayreach.robots import get_robot

    summary = rollout_batched(checkpoint, episodes=worlds, goal_tolerance=GOAL_TOLERANCE,
                              n_obstacles=get_robot(robot).task_obstacles, seed=SELECTION_SEED,
                              split="validation", suite=suite)
    rates = {f"{outcome}_rate": round(count / summary.episodes, 4) for outcome, count in summary.outcomes.items()}
    return {**rates, "score": round(score(summary.success_rate, summary.collision_rate), 4), "worlds": worlds}


def record(out: Path, row: dict[str, Any], best: dict[str, Any] | None) -> bool:
    """Append ``row`` (a validation at ``row["timesteps"]``) to the run's validation.csv and
    say whether it beats ``best``, the best row so far (a tie keeps the earlier one)."""
    path = out / VALIDATION_CSV
    new = not path.exists()
    with path.open("a", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(row))
        if new:
            writer.writeheader()
        writer.writerow(row)
    return best is None or row["score"] > best["score"]


def keep_best(out: Path, checkpoint: Path) -> Path:
    """Copy the checkpoint that just scored best to the run's ``best.zip``."""
    return Path(shutil.copyfile(checkpoint, out / BEST))


def read_validation(out: Path) -> list[dict[str, float]]:
    """The rows of a run's validation.csv (none where it has none)."""
    path = out / VALIDATION_CSV
    if not path.exists():
        return []
    with path.open(newline="") as handle:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(handle)]
