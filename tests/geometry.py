"""Independent geometry for the tests: exact signed distances to the primitive obstacles."""

from __future__ import annotations

import numpy as np

from rayreach.scenarios.schema import ObstacleSpec
from rayreach.sim.transforms import rpy_to_matrix


def signed_distance(obs: ObstacleSpec, points: np.ndarray, t: float = 0.0) -> np.ndarray:
    """Signed distance (m, negative inside) of points (n, 3) to a box, sphere or cylinder
    (cylinder axis = local z), with the obstacle where it is ``t`` seconds after the start."""
    centre = np.asarray(obs.position_at(t), dtype=float)
    local = (np.atleast_2d(np.asarray(points, dtype=float)) - centre) @ rpy_to_matrix(obs.rpy)
    if obs.shape == "sphere":
        return np.linalg.norm(local, axis=1) - obs.radius
    if obs.shape == "box":
        excess = np.abs(local) - np.asarray(obs.half_extents)
    elif obs.shape == "cylinder":
        excess = np.stack(
            (np.hypot(local[:, 0], local[:, 1]) - obs.radius, np.abs(local[:, 2]) - obs.height / 2), 1
        )
    else:
        raise ValueError(f"no signed distance for shape {obs.shape}")
    return np.linalg.norm(np.maximum(excess, 0.0), axis=1) + np.minimum(excess.max(axis=1), 0.0)


def segment_hits(obstacles, a, b, step: float = 5e-4, t: float = 0.0) -> list[int]:
    """Indices of the obstacles that the segment a-b passes through (sampled every ``step``)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    n = max(2, int(np.ceil(np.linalg.norm(b - a) / step)) + 1)
    points = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
    return [i for i, o in enumerate(obstacles) if np.any(signed_distance(o, points, t) < 0.0)]
