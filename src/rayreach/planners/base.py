"""The two kinds of planner the executor runs.

A :class:`GlobalPlanner` answers a joint-space query at once with a path (RRT, NC-RRT,
OMPL); a :class:`ReactivePlanner` chooses one action per control step from what it senses
(the DRL policy). Both report their full configuration, stored with every run.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import asdict, dataclass
from typing import Any, Callable

import numpy as np

from rayreach.acting.config import ActingConfig
from rayreach.env.observation import ObservationConfig
from rayreach.planners.collision import CollisionChecker
from rayreach.planners.result import PlanResult
from rayreach.planners.smoothing import ShortcutConfig, shortcut


class GlobalPlanner(ABC):
    name: str

    @abstractmethod
    def plan(self, checker: CollisionChecker, q_start: np.ndarray, q_goal: np.ndarray,
             rng: np.random.Generator) -> PlanResult:
        """A path from ``q_start`` to ``q_goal`` on the scene as ``checker`` sees it now."""

    @abstractmethod
    def config(self) -> dict[str, Any]:
        """Every parameter, for the results database."""


class ReactivePlanner(ABC):
    name: str
    acting: ActingConfig = ActingConfig()
    """The acting layers the executor runs the planner's actions through
    (``ActingConfig.off()``: the actions as they come, as the paper's agent acted)."""
    observation: ObservationConfig = ObservationConfig()
    """What the planner's observations hold (``rayreach.env.observation``)."""

    def reset(self, seed: int) -> None:
        """Called before each run with the run's seed (for a planner that draws at random)."""

    def refusal(self, start: np.ndarray, goals: np.ndarray) -> str | None:
        """Why the planner will not run a query from tool position ``start`` to ``goals``
        (recorded as ``outside training``); None: it will (every planner but a policy trained
        elsewhere)."""
        return None

    @abstractmethod
    def act(self, observation: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        """The action for this control step; ``info``: the last step's (or reset's)."""

    @abstractmethod
    def config(self) -> dict[str, Any]:
        """Every parameter, for the results database."""


@dataclass
class SamplingPlanner(GlobalPlanner):
    """A sampling algorithm (``algorithm(start, goal, checker, rng, settings)``) with optional
    shortcut smoothing applied to its solution."""

    name: str
    algorithm: Callable[..., PlanResult]
    settings: Any
    smoothing: ShortcutConfig | None = None

    def plan(self, checker: CollisionChecker, q_start: np.ndarray, q_goal: np.ndarray,
             rng: np.random.Generator) -> PlanResult:
        result = self.algorithm(q_start, q_goal, checker, rng, self.settings)
        result.config = self.config()
        if result.solved and self.smoothing is not None:
            assert result.path is not None
            result.raw_path = result.path
            result.path = shortcut(result.path, checker, rng, self.smoothing)
        return result

    def config(self) -> dict[str, Any]:
        smoothing = asdict(self.smoothing) if self.smoothing is not None else None
        return {"planner": self.name, **asdict(self.settings), "smoothing": smoothing}
