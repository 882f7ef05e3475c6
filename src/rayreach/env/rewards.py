"""The paper's reward terms (eq. "total reward" and its parts), each a small pure function.

r = r_suc + r_c + r_d + r_shake + r_o + r_e with the paper's weights as defaults.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RewardWeights:
    success: float = 10.0
    """r_suc when the distance to the goal is below the goal tolerance and the robot touches
    nothing (a goal reached in contact ends the episode as a collision)."""
    collision: float = -10.0
    """r_c when the robot collides (the episode ends)."""
    distance: float = -0.01
    """r_d = distance * d_t, d_t in metres."""
    out_of_bounds: float = -10.0
    """r_o when the end effector leaves the workspace (the episode ends)."""
    exhausted: float = -5.0
    """r_e when the step budget is used up (the episode is truncated)."""
    shaking: float = -0.005
    """r_shake = shaking * n_s."""
    progress: float = 0.0
    """Not in the paper (0 there): progress * (d_{t-1} - d_t), a dense term for training."""
    progress_around_obstacles: bool = False
    """Not in the paper: the progress term measures the distance along the shortest way round
    the static obstacles (``rayreach.env.goal_field``), not the straight line, so that a goal
    behind a wall does not reward stopping at the wall."""
    proximity: float = 0.0
    """Not in the paper (0 there): proximity * (1 - f / proximity_range) for the shortest ray
    fraction f below ``proximity_range``: a warning before a collision, for training."""
    proximity_range: float = 0.25
    """Ray fraction (of the 0.4 m range) under which the proximity term starts."""
    shielded: float = 0.0
    """Not in the paper (0 there): shielded * the share of the commanded translation the
    safety layer removed. With the layer on in training a drive into an obstacle is held
    instead of ending with r_c; this keeps a prompt cost on it."""


def success_reward(distance: float, tolerance: float, w: RewardWeights = RewardWeights()) -> float:
    return w.success if distance < tolerance else 0.0


def collision_reward(collided: bool, w: RewardWeights = RewardWeights()) -> float:
    return w.collision if collided else 0.0


def distance_reward(distance: float, w: RewardWeights = RewardWeights()) -> float:
    return w.distance * distance


def out_of_bounds_reward(outside: bool, w: RewardWeights = RewardWeights()) -> float:
    return w.out_of_bounds if outside else 0.0


def exhausted_reward(exhausted: bool, w: RewardWeights = RewardWeights()) -> float:
    return w.exhausted if exhausted else 0.0


def shaking_reward(n_shakes: int, w: RewardWeights = RewardWeights()) -> float:
    return w.shaking * n_shakes


def progress_reward(previous_distance: float, distance: float, w: RewardWeights = RewardWeights()) -> float:
    """0 where either distance is infinite (a way measured round obstacles from inside one)."""
    delta = previous_distance - distance
    return w.progress * delta if math.isfinite(delta) else 0.0


def proximity_reward(min_fraction: float, w: RewardWeights = RewardWeights()) -> float:
    return w.proximity * max(0.0, 1.0 - min_fraction / w.proximity_range)


def shielded_reward(commanded: np.ndarray, executed: np.ndarray, w: RewardWeights = RewardWeights()) -> float:
    """``commanded`` and ``executed`` translations (m); 0 when nothing was commanded."""
    size = float(np.linalg.norm(commanded))
    return w.shielded * float(np.linalg.norm(commanded - executed)) / size if size > 0 else 0.0


def count_uneven_movements(distances: list[float] | deque[float]) -> int:
    """n_s of the paper's algorithm: direction changes of the distance in the recorded window.

    Each consecutive pair is labelled 0 when the distance did not decrease (``d[i+1] - d[i] >= 0``)
    and 1 when it decreased; n_s counts label changes between neighbouring pairs.
    """
    d = list(distances)
    labels = [0 if d[i + 1] - d[i] >= 0 else 1 for i in range(len(d) - 1)]
    return sum(1 for j in range(len(labels) - 1) if labels[j] != labels[j + 1])


class ShakeCounter:
    """The queue Q_d of the paper's algorithm: pops the oldest distance once it holds more
    than ``window`` values, then appends the new one (so at most ``window + 1`` distances,
    ``window`` movements, are compared)."""

    def __init__(self, window: int = 10) -> None:
        self.window = window
        self.queue: deque[float] = deque()

    def reset(self) -> None:
        self.queue.clear()

    def update(self, distance: float) -> int:
        if len(self.queue) > self.window:
            self.queue.popleft()
        self.queue.append(distance)
        return count_uneven_movements(self.queue)
