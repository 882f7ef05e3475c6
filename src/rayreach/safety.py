"""A safety layer between a policy's action and the arm: not in the paper, off in training.

A trained policy still drives into what its rays see and out of the workspace now and then
(docs/training.md, "Acting"). A cell's controller would not let it: a safety zone holds the
tool inside the workspace, and speed and separation monitoring stops motion towards a
nearby obstacle. ``SafetyLayer`` does both with what the agent itself observes (its rays,
its end-effector position) plus the workspace bounds; it never looks at the obstacles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SafetyLayer:
    workspace_guard: float = 0.0
    """Drop the translation towards a workspace bound once the step would bring the end
    effector within this distance of it, m, so the tool slides along the bound; 0: off
    (leaving the workspace ends the episode with the paper's penalty)."""
    ray_shield: float = 0.0
    """When a ray sees something nearer than this, m, drop the translation along that ray
    (towards what it sees) and the whole rotation; 0: off."""

    def __post_init__(self) -> None:
        for name in ("workspace_guard", "ray_shield"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0 (0 = off), got {getattr(self, name)}")

    @property
    def active(self) -> bool:
        return self.workspace_guard > 0 or self.ray_shield > 0

    def filter(self, delta: np.ndarray, ee_pos: np.ndarray, low: np.ndarray, high: np.ndarray,
               ray_distances: np.ndarray, ray_directions: np.ndarray) -> np.ndarray:
        """``delta`` (dx, dy, dz, rotation vector) as the arm may execute it. ``ray_distances``
        (m) and unit ``ray_directions`` are those of the current observation."""
        out = np.array(delta, dtype=float)
        if self.ray_shield > 0:
            near = np.flatnonzero(ray_distances < self.ray_shield)
            if near.size:
                out[3:] = 0.0
                for i in near[np.argsort(ray_distances[near])]:
                    towards = out[:3] @ ray_directions[i]
                    if towards > 0:
                        out[:3] -= towards * ray_directions[i]
        if self.workspace_guard > 0:
            target = ee_pos + out[:3]
            leaving = ((target > high - self.workspace_guard) & (out[:3] > 0)) | (
                (target < low + self.workspace_guard) & (out[:3] < 0))
            out[:3][leaving] = 0.0
        return out


ACTING_SAFETY = SafetyLayer(workspace_guard=0.01, ray_shield=0.05)
"""The layer the executor and ``rollout`` act with: two 5 mm steps from a bound, and the
final approach's 5 cm clearance (``rayreach.policy.FinalApproach``)."""
