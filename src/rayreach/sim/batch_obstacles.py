"""The obstacles of N worlds as padded arrays, the layout the batched kernels read.

World ``i`` holds ``n_box[i]`` boxes in rows ``[i, :n_box[i]]`` of the box arrays and
``n_sphere[i]`` spheres likewise; rows past the count are padding and never read. The
arrays grow when a world brings more obstacles than any before it. A moving obstacle
(``ObstacleSpec.velocity``) goes from ``start`` along ``direction`` at ``speed``, back and
forth over ``travel`` metres when ``travel > 0``, as ``ObstacleSpec.position_at`` moves it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import numba
import numpy as np

from rayreach.sim.transforms import rpy_to_matrix

if TYPE_CHECKING:
    from rayreach.scenarios.schema import ObstacleSpec

BATCH_SHAPES = ("box", "sphere")
"""Obstacle shapes the batched environment handles (random worlds and exp1..exp7 use only these)."""


class ShapeRows:
    """One shape class of N worlds: positions now, fixed rotations and sizes, motion."""

    def __init__(self, n_worlds: int, size_dims: int) -> None:
        self.count = np.zeros(n_worlds, dtype=np.int64)
        self._size_dims = size_dims
        self._allocate(n_worlds, 1)

    def _allocate(self, n_worlds: int, rows: int) -> None:
        self.pos = np.zeros((n_worlds, rows, 3))
        self.rot = np.tile(np.eye(3), (n_worlds, rows, 1, 1))
        self.size = np.zeros((n_worlds, rows, self._size_dims))
        """Box half extents (3), or sphere radius (1)."""
        self.start = np.zeros((n_worlds, rows, 3))
        self.direction = np.zeros((n_worlds, rows, 3))
        self.speed = np.zeros((n_worlds, rows))
        self.travel = np.zeros((n_worlds, rows))
        """Back and forth over this distance, m; 0: keeps going."""

    @property
    def rows(self) -> int:
        return self.pos.shape[1]

    def grow(self, rows: int) -> None:
        """Room for ``rows`` obstacles per world, keeping what is there."""
        if rows <= self.rows:
            return
        old = {name: getattr(self, name)
               for name in ("pos", "rot", "size", "start", "direction", "speed", "travel")}
        self._allocate(len(self.count), rows)
        for name, array in old.items():
            getattr(self, name)[:, : array.shape[1]] = array

    def fill(self, world: int, obstacles: Sequence[ObstacleSpec]) -> None:
        self.grow(len(obstacles))
        self.count[world] = len(obstacles)
        for k, obs in enumerate(obstacles):
            self.start[world, k] = obs.position
            self.pos[world, k] = obs.position
            self.rot[world, k] = rpy_to_matrix(obs.rpy)
            self.size[world, k] = obs.half_extents if obs.shape == "box" else (obs.radius,)
            velocity = np.asarray(obs.velocity, dtype=float)
            speed = float(np.sqrt(velocity @ velocity))
            self.speed[world, k] = speed
            self.direction[world, k] = velocity / speed if speed > 0 else 0.0
            self.travel[world, k] = obs.travel or 0.0


class ObstacleBatch:
    """Boxes and spheres of ``n_worlds`` worlds (see the module docstring)."""

    def __init__(self, n_worlds: int) -> None:
        self.n_worlds = n_worlds
        self.boxes = ShapeRows(n_worlds, 3)
        self.spheres = ShapeRows(n_worlds, 1)
        self.moving = np.zeros(n_worlds, dtype=bool)
        """Whether a world has any moving obstacle."""

    def set_world(self, world: int, obstacles: Sequence[ObstacleSpec]) -> None:
        """Replace world ``world``'s obstacles (at their positions at time 0)."""
        unknown = sorted({o.shape for o in obstacles} - set(BATCH_SHAPES))
        if unknown:
            raise ValueError(f"the batched environment handles {' and '.join(BATCH_SHAPES)} obstacles, "
                             f"not {', '.join(unknown)}; use ReachEnv for such scenes")
        self.boxes.fill(world, [o for o in obstacles if o.shape == "box"])
        self.spheres.fill(world, [o for o in obstacles if o.shape == "sphere"])
        self.moving[world] = any(o.moving for o in obstacles)

    def at_time(self, time: np.ndarray) -> None:
        """Move every moving obstacle to where it is at each world's ``time`` (N,), s."""
        for rows in (self.boxes, self.spheres):
            _move(rows.pos, rows.start, rows.direction, rows.speed, rows.travel, rows.count, self.moving,
                  time)


@numba.njit(cache=True)
def _move(pos, start, direction, speed, travel, count, moving, time):  # pragma: no cover - compiled
    for i in range(pos.shape[0]):
        if not moving[i]:
            continue
        for k in range(count[i]):
            if speed[i, k] == 0.0:
                continue
            s = speed[i, k] * time[i]
            span = travel[i, k]
            if span > 0.0:
                s = s % (2.0 * span)
                if s > span:
                    s = 2.0 * span - s
            for j in range(3):
                pos[i, k, j] = start[i, k, j] + direction[i, k, j] * s
