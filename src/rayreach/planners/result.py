"""What every planner returns: one status, the path (only when solved), timing, its config."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import Any

import numpy as np


class Status(str, Enum):
    SOLVED = "solved"
    TIMEOUT = "timeout"
    INVALID_START = "invalid start"
    GOAL_IN_COLLISION = "goal in collision"
    GOAL_UNREACHABLE = "goal unreachable"
    CRASH = "crash"
    OUTSIDE_TRAINING = "outside training"
    """A DRL planner refused the query: its start or a goal lies outside the workspace the
    policy was trained in (``DRLPlanner.refusal``); a sampling planner can plan it."""


@dataclass
class PlanResult:
    status: Status
    path: list[np.ndarray] | None
    """Joint-space waypoints from start to goal; None unless solved."""
    planning_time: float
    iterations: int
    config: dict[str, Any] = field(default_factory=dict)
    """Every parameter of the planner that produced this, for traceability."""
    message: str = ""
    raw_path: list[np.ndarray] | None = None
    """The path as the planner found it, before smoothing (None when not smoothed)."""

    @property
    def solved(self) -> bool:
        return self.status is Status.SOLVED

    @property
    def joint_path_length(self) -> float:
        if not self.path or len(self.path) < 2:
            return 0.0
        return float(np.linalg.norm(np.diff(np.asarray(self.path), axis=0), axis=1).sum())
