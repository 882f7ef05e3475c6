"""Choosing a run's best checkpoint on validation worlds while it trains.

A policy's success alone on fresh worlds does not rise steadily with training: the KR16's
default run gained two points between 40 and 50 M decisions, and its rate with the acting
stack was higher at 23 M than at 40 M (docs/training.md). So every ``validate_every``
decisions the run plays its checkpoint alone, deterministic, at the true 1 cm goal on
``validate_worlds`` validation worlds of the robot's task (``task_obstacles``), writes the
figures to ``validation.csv`` and keeps the best checkpoint so far as ``best.zip``: what
``rayreach export`` ships from a run directory. The worlds start at ``SELECTION_SEED``,
apart from the validation split's first worlds, which the docs' tuning figures use, so a
figure quoted there is not the figure a checkpoint was chosen on.
"""

from __future__ import annotations

import os
import random
import shutil
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

import numpy as np

VALIDATION_CSV = "validation.csv"
BEST = "best.zip"
SELECTION_SEED = 2_000_000
"""First validation seed of the worlds a run chooses its checkpoint on."""
GOAL_TOLERANCE = 0.01
"""The true goal size: a checkpoint is judged where the policy is used."""
BROAD_ELEMENTS = 3
"""Scene elements of a broad world judged (the goal's table, shelf or box and two more), as
the docs measure the broad suite."""


def task_obstacles(robot: str, suite: str) -> int:
    """Obstacles (broad worlds: scene elements) per world a checkpoint is judged on."""
    from rayreach.robots import get_robot
    from rayreach.scenarios import RANDOM

    return get_robot(robot).task_obstacles if suite == RANDOM else BROAD_ELEMENTS


def score(success_rate: float, collision_rate: float) -> float:
    """What a checkpoint is ranked by: success less collisions (a collision costs a
    robot more than a timeout does, and the targets bound both)."""
    return success_rate - collision_rate


def beats(row: dict[str, Any], best: dict[str, Any] | None) -> bool:
    """Whether a validation ``row`` beats the best so far (a tie keeps the earlier one)."""
    return best is None or row["score"] > best["score"]


@contextmanager
def training_untouched() -> Iterator[None]:
    """Leave the run's random generators and torch threads as they were: loading a policy
    reseeds Python's, NumPy's and torch's global generators (SB3's ``set_random_seed``) and
    sets one thread, and training draws its action noise and minibatches from them."""
    import torch

    states = random.getstate(), np.random.get_state(), torch.get_rng_state()
    threads = torch.get_num_threads()
    try:
        yield
    finally:
        random.setstate(states[0])
        np.random.set_state(states[1])
        torch.set_rng_state(states[2])
        torch.set_num_threads(threads)


def validate(checkpoint: Path, robot: str, suite: str, worlds: int) -> dict[str, Any]:
    """The checkpoint alone on the selection worlds: its outcome rates and score."""
    from rayreach.evaluate.rollout import rollout_batched

    n_obstacles = task_obstacles(robot, suite)
    with training_untouched():
        summary = rollout_batched(checkpoint, episodes=worlds, goal_tolerance=GOAL_TOLERANCE, n_obstacles=n_obstacles,
                                  seed=SELECTION_SEED, split="validation", suite=suite)
    rates = {f"{outcome}_rate": round(count / summary.episodes, 4) for outcome, count in summary.outcomes.items()}
    return {**rates, "score": round(score(rates["success_rate"], rates["collision_rate"]), 4), "worlds": worlds,
            "obstacles": n_obstacles}


def keep_best(out: Path, checkpoint: Path) -> Path:
    """Copy the checkpoint that just scored best to the run's ``best.zip``, whole or not at all."""
    partial = out / (BEST + ".part")
    shutil.copyfile(checkpoint, partial)
    os.replace(partial, out / BEST)
    return out / BEST


def read_validation(out: Path) -> list[dict[str, float]]:
    """The rows of a run's validation.csv (none where it has none)."""
    import csv

    path = out / VALIDATION_CSV
    if not path.exists():
        return []
    with path.open(newline="") as handle:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(handle)]
