"""Shortcut smoothing: replace a stretch of a joint path by a straight segment when it is valid.

Off by default (the paper's planners did not smooth); every sampling planner takes it with
``smooth=True``, and results keep the path length before and after.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rayreach.planners.collision import CollisionChecker


@dataclass(frozen=True)
class ShortcutConfig:
    attempts: int = 200
    """Random shortcut attempts (each tries to join two random path points directly)."""
    resolution: float = 0.02
    """Edge check resolution, rad per joint (the planners' default)."""


def path_length(path: list[np.ndarray]) -> float:
    """Joint-space length (sum of Euclidean segment lengths), rad."""
    if len(path) < 2:
        return 0.0
    return float(np.linalg.norm(np.diff(np.asarray(path), axis=0), axis=1).sum())


def shortcut(path: list[np.ndarray], checker: CollisionChecker, rng: np.random.Generator,
             config: ShortcutConfig = ShortcutConfig()) -> list[np.ndarray]:
    """Random shortcutting on the path's points (start and goal are kept exactly); the result
    is never longer than the input and every new edge passed ``checker.edge_valid``."""
    points = [np.asarray(q, dtype=float) for q in path]
    for _ in range(config.attempts):
        if len(points) < 3:
            break
        i, j = sorted(rng.choice(len(points), size=2, replace=False))
        if j - i < 2:
            continue
        if checker.edge_valid(points[i], points[j], config.resolution):
            points = points[: i + 1] + points[j:]
    return points
