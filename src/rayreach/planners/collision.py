"""The one collision check shared by the planners and the executor."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from rayreach.planners.result import PlanResult, Status
from rayreach.sim.scene import Scene


class CollisionChecker:
    """Valid = within the joint limits and no robot-obstacle penetration (PyBullet meshes).

    Obstacles are wherever the scene has them now (planners plan at t = 0). ``checks``
    counts configuration checks, for the checks-per-second figure.
    """

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self.lower = scene.spec.lower_array
        self.upper = scene.spec.upper_array
        self.checks = 0

    def valid(self, q: np.ndarray) -> bool:
        self.checks += 1
        if np.any(q < self.lower) or np.any(q > self.upper):
            return False
        self.scene.set_joints(q)
        return not self.scene.in_collision()

    def edge_valid(self, qa: np.ndarray, qb: np.ndarray, resolution: float) -> bool:
        """Every configuration on the straight joint-space segment, at most ``resolution`` rad
        apart in any joint, is valid (``qa`` itself is assumed checked)."""
        n = max(1, math.ceil(float(np.max(np.abs(qb - qa))) / resolution))
        for i in range(1, n + 1):
            if not self.valid(qa + (qb - qa) * (i / n)):
                return False
        return True


def refuse_endpoints(checker: CollisionChecker, start: np.ndarray, goal: np.ndarray, config: dict[str, Any],
                     t0: float) -> PlanResult | None:
    """The result that stops a query before any search (invalid start, goal in collision),
    or None when both ends are valid; ``t0`` is when planning began (``perf_counter``)."""
    if not checker.valid(start):
        status = Status.INVALID_START
    elif not checker.valid(goal):
        status = Status.GOAL_IN_COLLISION
    else:
        return None
    return PlanResult(status, None, time.perf_counter() - t0, 0, config)


def sampling_box(checker: CollisionChecker, start: np.ndarray, goal: np.ndarray,
                 margin: float | None) -> tuple[np.ndarray, np.ndarray]:
    """The joint box spanned by start and goal, widened by ``margin`` rad per joint and kept
    within the limits; the full joint range when ``margin`` is None."""
    if margin is None:
        return checker.lower, checker.upper
    low = np.maximum(checker.lower, np.minimum(start, goal) - margin)
    high = np.minimum(checker.upper, np.maximum(start, goal) + margin)
    return low, high


def finish_with_recheck(path: list[np.ndarray], checker: CollisionChecker, resolution: float,
                        config: dict[str, Any], planning_time: float, iterations: int = 0) -> PlanResult:
    """A found path counts only after the shared checker accepts every edge; otherwise the
    planner has a bug and the run is a crash, never a fake success."""
    for qa, qb in zip(path[:-1], path[1:]):
        if not checker.edge_valid(qa, qb, resolution):
            return PlanResult(Status.CRASH, None, planning_time, iterations, config,
                              "the returned path failed the shared collision re-check")
    return PlanResult(Status.SOLVED, path, planning_time, iterations, config)
