"""Distances from points to segments and parallelograms, and capsules round point sets: how the
acting layers measure the tool and the arm against what the rays hit, and how the batched
collision test bounds the arm's links."""

from __future__ import annotations

import numpy as np


def distances_to_segment(points: np.ndarray, a: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Distance of each point (n, 3) to the segment from ``a`` to ``a + d`` (a point if d = 0)."""
    rel = points - a
    t = np.clip((rel @ d) / (d @ d), 0.0, 1.0) if d @ d > 0 else np.zeros(len(points))
    return np.linalg.norm(rel - t[:, None] * d, axis=1)


def distances_to_parallelogram(points: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Distance of each point (n, 3) to the parallelogram {s u + t v : s, t in [0, 1]}; a
    zero or degenerate side makes it a segment or a point."""
    zero = np.zeros(3)
    best = np.minimum.reduce([distances_to_segment(points, a, d) for a, d in ((zero, u), (v, u), (zero, v), (u, v))])
    gram = np.array([[u @ u, u @ v], [u @ v, v @ v]])
    if np.linalg.det(gram) > 1e-12 * max(gram[0, 0] * gram[1, 1], 1e-30):
        st = np.linalg.solve(gram, np.stack([points @ u, points @ v]))
        inside = np.all((st >= 0.0) & (st <= 1.0), axis=0)
        if inside.any():
            foot = st[0, inside, None] * u + st[1, inside, None] * v
            best[inside] = np.linalg.norm(points[inside] - foot, axis=1)
    return best


def capsule_around(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The capsule (segment ends a, b and radius) around ``vertices`` along their principal
    axis: it holds every vertex, hence the convex mesh they span."""
    centre = vertices.mean(axis=0)
    axis = np.linalg.svd(vertices - centre, full_matrices=False)[2][0]
    along = (vertices - centre) @ axis
    a, b = centre + along.min() * axis, centre + along.max() * axis
    return a, b, float(distances_to_segment(vertices, a, b - a).max())
