"""The one collision check shared by the planners and the executor."""

from __future__ import annotations

import math

import numpy as np

from rayreach.scene import Scene


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
