"""Rays from the tool towards the goal: is the straight way there clear?

The paper's rays look out from the arm in fixed directions. A plate a few millimetres thick
lying over the goal, which the tool meets edge-on or from above, falls between them: the
UR5's policy dives at a goal it cannot tell is covered (docs/log/2026-12-05-cover-sight.md).
Three rays aimed at the goal ask the question directly. Each is parallel to goal minus tip
and as long as that offset: from the tip (the tip's straight way to the goal), from the
tool's middle and from the flange (where the tool's body would pass if it went there without
turning). Their hit fractions read 1 where the way is clear. A depth camera's pixels towards
the goal give the same reading on a real cell; here they are cast like the other rays.
"""

from __future__ import annotations

import numpy as np

GOAL_RAY_POINTS = np.array([0.0, 0.5, 1.0])
"""Where the rays start, as shares of the tool's length back from the tip towards the flange."""
N_GOAL_RAYS = len(GOAL_RAY_POINTS)
SHORTEST = 1e-4
"""Rays are at least this long, m; at the goal they point along the tool."""


def goal_rays(tip: np.ndarray, tool_direction: np.ndarray, goal: np.ndarray, tool_length: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The goal rays of n poses: origins and unit directions (n, 3, 3), and each pose's ray
    length (n,), m. ``tip``, ``tool_direction`` (flange to tip, unit) and ``goal`` are (n, 3)."""
    offset = goal - tip
    distance = np.linalg.norm(offset, axis=1)
    far = distance > SHORTEST
    direction = np.where(far[:, None], offset / np.maximum(distance, SHORTEST)[:, None], tool_direction)
    origins = tip[:, None, :] - (GOAL_RAY_POINTS * tool_length)[None, :, None] * tool_direction[:, None, :]
    directions = np.repeat(direction[:, None, :], N_GOAL_RAYS, axis=1)
    return origins, directions, np.maximum(distance, SHORTEST)
