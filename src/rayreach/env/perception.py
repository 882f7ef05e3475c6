"""What the arm senses in one step, as arrays: the rays in the world, the pose, the goal."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np


def seen_points(origins: np.ndarray, directions: np.ndarray, fractions: np.ndarray, ray_range: float) -> np.ndarray:
    """The world points rays of ``ray_range`` see, m (k, 3): those reading under 1 (of ``fractions``)."""
    hit = fractions < 1.0
    return origins[hit] + directions[hit] * (fractions[hit] * ray_range)[:, None]


@dataclass(frozen=True)
class Perception:
    """One step's sensing, computed once (``ReachEnv.perceive``) and shared by every layer that
    acts on it. Arrays are the environment's own: read them, never write."""

    step: int
    """Steps taken in the episode so far."""
    q: np.ndarray
    """Joint angles, rad (6,)."""
    ee_position: np.ndarray
    """End-effector position in the world, m (3,)."""
    ee_rotation: np.ndarray
    """End-effector orientation in the world (3, 3); its third column points along the tool."""
    goal: np.ndarray
    """The current goal, m (3,)."""
    origins: np.ndarray
    """Ray origins in the world, m (n, 3)."""
    directions: np.ndarray
    """Unit ray directions in the world (n, 3)."""
    lengths: np.ndarray
    """How far each ray sees, m (n,): the ray's range where it sees nothing."""
    fractions: np.ndarray
    """The observation's hit fractions in [0, 1] (n,); 1: nothing within range."""
    workspace_low: np.ndarray
    workspace_high: np.ndarray
    """The workspace box, m (3,) each."""
    arm_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    """Points the rays round the upper arm and the forearm see, in the world, m (k, 3):
    where the arm's rule reads them (``SafetyLayer.arm_rays``), else none."""

    @property
    def goal_offset(self) -> np.ndarray:
        """Goal minus end effector, m (3,)."""
        return self.goal - self.ee_position

    @property
    def tool_direction(self) -> np.ndarray:
        """Unit vector from the flange to the tool's tip (3,)."""
        return self.ee_rotation[:, 2]

    @cached_property
    def hit_points(self) -> np.ndarray:
        """The points the rays see, in the world, m (k, 3); rays that see nothing within range
        are left out."""
        hit = self.fractions < 1.0
        return self.origins[hit] + self.directions[hit] * self.lengths[hit, None]

    @property
    def hits(self) -> np.ndarray:
        """The points the rays see, relative to the end effector, m (k, 3)."""
        return self.hit_points - self.ee_position
