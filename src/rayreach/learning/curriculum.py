"""Training curricula: the paper's augmented goal size and an obstacle count that follows success.

Both are plain state machines fed with episode outcomes; the trainer keeps one instance of
each for all its environments together and pushes their values to every environment.
"""

from __future__ import annotations

from collections import deque
from dataclasses import asdict, dataclass, field
from typing import Any


@dataclass(frozen=True)
class GoalSizeParams:
    """Paper table "Parameters for augmented target size"."""

    rho: float = 0.1
    """rho: the size used for the first e_zeta episodes. The paper does not give it; starting
    "larger than life" at rho_max is the reading that matches its text."""
    rho_max: float = 0.1
    rho_min: float = 0.01
    delta_plus: float = 0.001
    delta_minus: float = 0.01
    e_zeta: int = 1000
    p_zeta: float = 0.9
    k: int = 50


def next_goal_size(previous: float, episode: int, eta: float, p: GoalSizeParams) -> float:
    """rho~(e) from rho~(e-1), the episode index e and eta(k, e) (paper eq. "augmented size").

    The paper's conditions on rho~(e) are read as conditions on rho~(e-1) (the value being
    updated); a step never leaves [rho_min, rho_max].
    """
    if episode < p.e_zeta:
        return p.rho
    if eta < p.p_zeta and previous < p.rho_max:
        return min(previous + p.delta_plus, p.rho_max)
    if eta >= p.p_zeta and previous > p.rho_min:
        return max(previous - p.delta_minus, p.rho_min)
    if eta == 1.0 and previous == p.rho:
        return p.rho
    return previous


@dataclass
class AugmentedGoalSize:
    """rho~ across all environments: one episode counter e and one window of S_e."""

    params: GoalSizeParams = field(default_factory=GoalSizeParams)
    size: float = -1.0
    episode: int = 0
    window: deque = field(default_factory=deque)

    def __post_init__(self) -> None:
        if self.size < 0:
            self.size = self.params.rho
        self.window = deque(self.window, maxlen=self.params.k)

    def eta(self) -> float:
        """eta(k, e): successes among the last k episodes, over k (fewer at the start)."""
        return sum(self.window) / self.params.k

    def record(self, success: bool) -> float:
        """Feed S_e of the episode that just ended; returns rho~ for the next episode."""
        self.window.append(1 if success else 0)
        self.episode += 1
        self.size = next_goal_size(self.size, self.episode, self.eta(), self.params)
        return self.size

    def state(self) -> dict[str, Any]:
        return {"size": self.size, "episode": self.episode, "window": list(self.window), "params": asdict(self.params)}

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "AugmentedGoalSize":
        return cls(GoalSizeParams(**state["params"]), state["size"], state["episode"], deque(state["window"]))


@dataclass(frozen=True)
class ObstacleParams:
    """Obstacle curriculum: the count goes up by one once ``window`` episodes played at the
    true goal size have a success rate of at least ``raise_at``, and down by one once
    ``window`` episodes of any goal size have one below ``lower_at``; it stays within
    [minimum, maximum]."""

    start: int = 1
    """Not 0: a policy first trained in empty worlds learns to rush straight at the goal and
    loses its exploration noise before obstacles arrive (docs/training.md)."""
    minimum: int = 0
    maximum: int = 3
    window: int = 200
    raise_at: float = 0.8
    lower_at: float = 0.3
    mix: bool = False
    """Spread the worlds evenly over 1 to the count (``world_counts``) instead of putting
    every world at the count. In broad worlds success at the true goal size stayed under
    ``raise_at``, and a run trained 80 % of its decisions on one element and none on three,
    the count it is measured at (docs/training.md, "Broad worlds")."""

    def world_counts(self, count: int, n_worlds: int) -> list[int]:
        """Each world's obstacle count while the curriculum stands at ``count``: the count, or
        with ``mix`` 1, 2, .. ``count`` in turn (0 stays 0)."""
        if not self.mix or count < 1:
            return [count] * n_worlds
        return [1 + i % count for i in range(n_worlds)]


@dataclass
class ObstacleCurriculum:
    params: ObstacleParams = field(default_factory=ObstacleParams)
    count: int = -1
    successes: int = 0
    episodes: int = 0
    true_successes: int = 0
    true_episodes: int = 0

    def __post_init__(self) -> None:
        if self.count < 0:
            self.count = self.params.start

    def record(self, success: bool, at_true_size: bool = True) -> int:
        """Feed one episode's outcome; returns the obstacle count for the next episodes.

        Only episodes played at the true goal size count towards raising: while the goal is
        enlarged, the goal-size curriculum keeps success near 90 % whatever the skill."""
        p = self.params
        self.episodes += 1
        self.successes += int(success)
        if at_true_size:
            self.true_episodes += 1
            self.true_successes += int(success)
        if self.true_episodes >= p.window:
            if self.true_successes / self.true_episodes >= p.raise_at and self.count < p.maximum:
                self.count += 1
                self.successes = self.episodes = 0
            self.true_successes = self.true_episodes = 0
        if self.episodes >= p.window:
            if self.successes / self.episodes < p.lower_at and self.count > p.minimum:
                self.count -= 1
                self.true_successes = self.true_episodes = 0
            self.successes = self.episodes = 0
        return self.count

    def state(self) -> dict[str, Any]:
        return {"count": self.count, "successes": self.successes, "episodes": self.episodes,
                "true_successes": self.true_successes, "true_episodes": self.true_episodes,
                "params": asdict(self.params)}

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "ObstacleCurriculum":
        return cls(ObstacleParams(**state["params"]), state["count"], state["successes"], state["episodes"],
                   state.get("true_successes", 0), state.get("true_episodes", 0))
