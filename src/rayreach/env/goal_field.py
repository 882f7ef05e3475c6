"""The tool tip's distance to the goal along the shortest way round the static obstacles.

The progress term of training (``RewardWeights.progress``) rewards each step by how much
nearer it brought the tool. Measured along the straight line, a goal behind a wall is a
trap: every way round starts by going away, so the policy stops at the wall's face (the
goal beside a wall, in a slot, in a shelf: 0 % alone before this, docs/training.md). Measured
along the shortest free path the same term points round the wall. The term stays a
difference of potentials, so it changes no optimal policy (Ng, Harada and Russell 1999),
and the policy never sees the field: it is training's privileged knowledge of the world.

The field is Dijkstra's distance on a grid over the workspace from the goal's neighbouring
cells, with 26 neighbours (steps of 1, sqrt 2, sqrt 3 cells) and no step that cuts the
corner of a blocked cell. A cell is blocked when its centre lies inside a static obstacle
grown by ``clearance_cells`` of a cell: at 0.75 of a cell every upright or flat plate,
however thin and turned, leaves no gap a path could slip through. Moving obstacles are left
out; they pass. A point's distance is the least of ``field + |point - centre|`` over the
eight centres round it that are free; where none is (next to an obstacle) it is infinite,
and the progress term then counts nothing for that step.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass
from typing import Sequence

import numba
import numpy as np

from rayreach.scenarios.schema import ObstacleSpec, Scenario
from rayreach.sim.transforms import rpy_to_matrix

FIELD_SHAPES = ("box", "sphere", "cylinder")
"""Obstacle shapes the field blocks; a mesh is left out (it never occurs in random worlds)."""


@dataclass(frozen=True)
class FieldConfig:
    cell: float = 0.02
    """Grid cell, m: the smallest the field uses."""
    max_cells: int = 60_000
    """A larger workspace gets larger cells, so that one field costs a few milliseconds to
    build (the KR16's 1.6 x 1.2 x 1.4 m box: 3.6 cm cells)."""
    clearance_cells: float = 0.75
    """How far, in cells, each obstacle is grown before cells are blocked."""

    def __post_init__(self) -> None:
        if not self.cell > 0:
            raise ValueError(f"cell must be positive, got {self.cell}")
        if self.max_cells < 8:
            raise ValueError(f"max_cells must be at least 8, got {self.max_cells}")
        if not self.clearance_cells >= 0.5:
            raise ValueError(f"clearance_cells must be >= 0.5 (thin plates would leak), got {self.clearance_cells}")

    def cell_for(self, size: np.ndarray) -> float:
        """The cell of a grid over a box of ``size`` (m): ``cell``, or larger to keep within ``max_cells``."""
        padded = np.asarray(size, dtype=float)
        cell = self.cell
        while np.prod(np.floor(padded / cell) + 3) > self.max_cells:
            cell *= 1.1
        return cell


@dataclass(frozen=True)
class GoalField:
    """One goal's distance field: ``values`` over a grid of ``dims`` cells from ``origin``
    (the first cell's centre), infinite where blocked or cut off."""

    origin: np.ndarray
    cell: float
    dims: np.ndarray
    values: np.ndarray
    goal: np.ndarray

    @classmethod
    def build(cls, obstacles: Sequence[ObstacleSpec], goal: np.ndarray, ws_low: np.ndarray, ws_high: np.ndarray,
              config: FieldConfig = FieldConfig()) -> "GoalField":
        """The field of ``goal`` in the workspace ``ws_low``..``ws_high`` round the static ``obstacles``."""
        low, high = np.asarray(ws_low, dtype=float), np.asarray(ws_high, dtype=float)
        goal = np.asarray(goal, dtype=float)
        cell = config.cell_for(high - low)
        dims = (np.floor((high - low) / cell).astype(np.int64) + 3)
        origin = low - cell  # one cell of margin either side: a tip just outside still has a value
        blocked = np.zeros(tuple(dims), dtype=bool)
        grow = config.clearance_cells * cell
        for o in obstacles:
            if not o.moving and o.shape in FIELD_SHAPES:
                _block(blocked, o, origin, cell, grow)
        values = _dijkstra(blocked.ravel(), dims, cell, origin, goal)
        return cls(origin, cell, dims, values, goal)

    def distance(self, point: np.ndarray) -> float:
        """The way from ``point`` to the goal, m (infinite inside a grown obstacle)."""
        p = np.asarray(point, dtype=float).reshape(1, 3)
        out = np.empty(1)
        _lookup(p, self.origin.reshape(1, 3), np.array([self.cell]), self.dims.reshape(1, 3),
                self.values.reshape(1, -1), np.zeros(1, dtype=np.int64), out)
        return float(out[0])


class FieldBatch:
    """The fields of N worlds in padded arrays, looked up for all worlds in one compiled call."""

    def __init__(self, n_worlds: int) -> None:
        self.origin = np.zeros((n_worlds, 3))
        self.cell = np.ones(n_worlds)
        self.dims = np.ones((n_worlds, 3), dtype=np.int64)
        self.values = np.full((n_worlds, 1), np.inf)

    def set_world(self, i: int, field: GoalField) -> None:
        size = len(field.values)
        if size > self.values.shape[1]:
            grown = np.full((len(self.values), size), np.inf)
            grown[:, : self.values.shape[1]] = self.values
            self.values = grown
        self.origin[i], self.cell[i], self.dims[i] = field.origin, field.cell, field.dims
        self.values[i, :size] = field.values
        self.values[i, size:] = np.inf

    def distances(self, points: np.ndarray, which: np.ndarray) -> np.ndarray:
        """The way to its goal of ``points[k]`` in world ``which[k]``."""
        out = np.empty(len(which))
        _lookup(np.asarray(points, dtype=float), self.origin, self.cell, self.dims, self.values,
                np.asarray(which, dtype=np.int64), out)
        return out


def scenario_field(scenario: Scenario, goal_index: int = 0, config: FieldConfig = FieldConfig()) -> GoalField:
    """The field of ``scenario``'s goal ``goal_index`` in its workspace."""
    return GoalField.build(scenario.obstacles, np.asarray(scenario.goals[goal_index], dtype=float),
                           np.asarray(scenario.workspace_low, dtype=float),
                           np.asarray(scenario.workspace_high, dtype=float), config)


def _block(blocked: np.ndarray, o: ObstacleSpec, origin: np.ndarray, cell: float, grow: float) -> None:
    """Block the cells of ``blocked`` (nx, ny, nz) whose centre lies within ``grow`` of ``o``,
    testing only the centres of its bounding box."""
    reach = grow + (float(np.linalg.norm(o.half_extents)) if o.shape == "box" else
                    math.hypot(o.radius, (o.height or 0.0) / 2))  # type: ignore[arg-type]
    centre = np.asarray(o.position, dtype=float)
    first = np.maximum(np.floor((centre - reach - origin) / cell).astype(np.int64), 0)
    last = np.minimum(np.ceil((centre + reach - origin) / cell).astype(np.int64) + 1, blocked.shape)
    if np.any(last <= first):
        return
    axes = [origin[a] + cell * np.arange(first[a], last[a]) for a in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    inside = _inside(o, grid.reshape(-1, 3), grow).reshape(grid.shape[:3])
    blocked[first[0]:last[0], first[1]:last[1], first[2]:last[2]] |= inside


def _inside(o: ObstacleSpec, points: np.ndarray, grow: float) -> np.ndarray:
    """Which ``points`` lie within ``grow`` of obstacle ``o`` (a box grown as a box)."""
    local = (points - np.asarray(o.position)) @ rpy_to_matrix(o.rpy)
    if o.shape == "box":
        assert o.half_extents is not None
        return (np.abs(local) <= np.asarray(o.half_extents) + grow).all(axis=1)
    assert o.radius is not None
    if o.shape == "sphere":
        return np.einsum("ij,ij->i", local, local) <= (o.radius + grow) ** 2
    assert o.height is not None
    radial = np.hypot(local[:, 0], local[:, 1])
    return (radial <= o.radius + grow) & (np.abs(local[:, 2]) <= o.height / 2 + grow)


_STEPS = np.array([(dx, dy, dz) for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1)
                   if (dx, dy, dz) != (0, 0, 0)], dtype=np.int64)


@numba.njit(cache=True)
def _dijkstra(blocked, dims, cell, origin, goal):  # pragma: no cover - compiled
    nx, ny, nz = dims[0], dims[1], dims[2]
    values = np.full(nx * ny * nz, np.inf)
    lengths = np.empty(len(_STEPS))
    for s in range(len(_STEPS)):
        lengths[s] = cell * math.sqrt(_STEPS[s, 0] ** 2 + _STEPS[s, 1] ** 2 + _STEPS[s, 2] ** 2)
    heap = [(0.0, np.int64(0))]
    heap.pop()
    gx = int(math.floor((goal[0] - origin[0]) / cell + 0.5))
    gy = int(math.floor((goal[1] - origin[1]) / cell + 0.5))
    gz = int(math.floor((goal[2] - origin[2]) / cell + 0.5))
    for x in range(max(gx - 1, 0), min(gx + 2, nx)):  # the free centres round the goal, at their true distance
        for y in range(max(gy - 1, 0), min(gy + 2, ny)):
            for z in range(max(gz - 1, 0), min(gz + 2, nz)):
                k = (x * ny + y) * nz + z
                if not blocked[k]:
                    d = math.sqrt((origin[0] + x * cell - goal[0]) ** 2 + (origin[1] + y * cell - goal[1]) ** 2
                                  + (origin[2] + z * cell - goal[2]) ** 2)
                    if d < values[k]:
                        values[k] = d
                        heapq.heappush(heap, (d, np.int64(k)))
    while heap:
        d, k = heapq.heappop(heap)
        if d > values[k]:
            continue
        x, rest = divmod(k, ny * nz)
        y, z = divmod(rest, nz)
        for s in range(len(_STEPS)):
            dx, dy, dz = _STEPS[s, 0], _STEPS[s, 1], _STEPS[s, 2]
            x2, y2, z2 = x + dx, y + dy, z + dz
            if x2 < 0 or y2 < 0 or z2 < 0 or x2 >= nx or y2 >= ny or z2 >= nz:
                continue
            k2 = (x2 * ny + y2) * nz + z2
            d2 = d + lengths[s]
            if d2 >= values[k2]:
                continue
            free = True  # no corner cut: every cell of the step's bounding box is free
            for cx in range(min(x, x2), max(x, x2) + 1):
                for cy in range(min(y, y2), max(y, y2) + 1):
                    for cz in range(min(z, z2), max(z, z2) + 1):
                        if blocked[(cx * ny + cy) * nz + cz]:
                            free = False
            if free:
                values[k2] = d2
                heapq.heappush(heap, (d2, k2))
    return values


@numba.njit(cache=True)
def _lookup(points, origin, cell, dims, values, which, out):  # pragma: no cover - compiled
    for n in range(len(which)):
        w = which[n]
        best = np.inf
        nx, ny, nz = dims[w, 0], dims[w, 1], dims[w, 2]
        base = np.empty(3, dtype=np.int64)
        for a in range(3):
            base[a] = int(math.floor((points[n, a] - origin[w, a]) / cell[w]))
        for x in range(base[0], base[0] + 2):  # the 8 centres round the point: none lies across a plate
            if x < 0 or x >= nx:
                continue
            for y in range(base[1], base[1] + 2):
                if y < 0 or y >= ny:
                    continue
                for z in range(base[2], base[2] + 2):
                    if z < 0 or z >= nz:
                        continue
                    v = values[w, (x * ny + y) * nz + z]
                    if v < np.inf:
                        d = v + math.sqrt((origin[w, 0] + x * cell[w] - points[n, 0]) ** 2
                                          + (origin[w, 1] + y * cell[w] - points[n, 1]) ** 2
                                          + (origin[w, 2] + z * cell[w] - points[n, 2]) ** 2)
                        if d < best:
                            best = d
        out[n] = best
