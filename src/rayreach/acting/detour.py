"""A way round what the rays have seen, for a policy that has stalled. Not in the paper.

A policy that hovers beside an obstacle it cannot cross (a goal slot under the workspace's
ceiling, a plate across its path) repeats itself until its step budget runs out
(docs/acting.md). ``Detour`` then plans a path for the tool's tip through a grid
over the workspace, keeping the tool, at its present orientation, clear of every point the
rays have hit in the episode, and treating what no ray has seen as free: a bug algorithm's
optimism, corrected as the rays see more. It steps along that path, replanning every few
steps, until the tool is within the final approach's radius of the goal. Like the rest of
the acting layers it never looks at the obstacles, only at the rays' hits.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import ClassVar, Sequence

import numpy as np

from rayreach.acting.final_approach import stalled
from rayreach.acting.memory import RayMemory
from rayreach.acting.shield import SafetyLayer
from rayreach.sim.voxels import cell_keys

VOXEL = 0.01
"""Hits are remembered once per cell of this size, m (a static surface is hit every step)."""


@dataclass(frozen=True)
class Detour:
    stall_steps: int = 100
    """Plan once the last this many steps brought the end effector less than ``stall_gain``
    nearer the goal (and as many steps have passed since the last detour ended)."""
    stall_gain: float = 0.01
    """Least progress towards the goal, m, over ``stall_steps`` steps."""
    cell: float = 0.02
    """Grid spacing, m."""
    clearance: float = 0.04
    """Least distance, m, between the tool's surface and any remembered hit on the path; on
    the detour's steps the safety layer's shield holds off only what is nearer than this
    (``shield``). A path between a goal slot's plates must fit (chosen from 3, 4 and 5 cm on
    random worlds, docs/acting.md)."""
    replan_steps: int = 10
    """Steps between plans while a detour is followed (the rays see more as it goes)."""
    behind: float = 0.15
    """How far past the tool's back the path also keeps clear, m: the wrist and forearm follow
    the tool and carry no rays, so a tool pointing down cannot pass just under a box."""
    held_steps: int = 5
    """End the detour after this many steps in which the arm held still (the safety layer's
    shield or the arm's rule refused what the path asks, which the path does not model);
    the policy acts again."""
    reach: float = 0.3
    """The grid spans the box round the end effector and the goal grown by this much, m,
    inside the workspace."""

    def shield(self, layer: SafetyLayer) -> SafetyLayer:
        """The safety layer for the detour's steps: ``layer`` with its ray shield narrowed to
        the clearance. The path keeps that far from everything seen; a 5 cm shield held a
        tool following a 3 cm path off the slot plates the path passes, and the detour gave
        up (docs/acting.md). What the shield still stops is what the plan did not
        know: something seen nearer than the clearance since."""
        return replace(layer, ray_shield=min(layer.ray_shield, self.clearance))

    def __post_init__(self) -> None:
        for name in ("stall_steps", "replan_steps", "held_steps"):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"{name} must be a whole number of steps >= 1, got {value}")
        for name in ("stall_gain", "cell", "reach"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")
        for name in ("clearance", "behind"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")


class DetourState:
    """One episode's detour: the hits seen so far, and the path being followed."""

    THROUGH: ClassVar[float] = 0.004
    """A ray passing this near a remembered hit, m, before it sees anything, shows it gone."""
    PASSED: ClassVar[float] = 0.02
    """... unless the ray's own hit lies within this distance beyond it, m (a ray grazing a
    surface passes near the surface's other points)."""

    LEAVE: ClassVar[float] = 0.1
    """The path starts from a free cell at most this far from the tool, m (the shield may
    hold the tool within the clearance of what it sees)."""

    def __init__(self, detour: Detour, memory: RayMemory, tool_length: float, tool_radius: float, arrive: float,
                 ray_range: float, low: np.ndarray, high: np.ndarray) -> None:
        self.detour = detour
        self.memory = memory
        """The episode's ray memory: every scan is taken in when a plan needs it (most runs never stall)."""
        self.tool_length = tool_length
        self.tool_radius = tool_radius
        self.arrive = arrive
        """The detour ends within this distance of the goal, m (the final approach's radius)."""
        self.ray_range = ray_range
        self.low, self.high = np.asarray(low, float), np.asarray(high, float)
        """The box the tip's path stays in, m."""
        self._keys = np.zeros(0, dtype=np.int64)
        self._points = np.zeros((0, 3))
        self._taken = 0  # scans of the memory taken in so far
        self._path: np.ndarray | None = None
        self._planned_at = 0
        self._since = 0  # the step from which a stall counts
        self._last: np.ndarray | None = None  # where the last detour step started
        self._held = 0

    def seen(self) -> np.ndarray:
        """Every remembered hit, (n, 3): each scan's rays, in turn, forget the hits they now
        pass through (a moving plate's trail, a goal cover gone) and add what they hit, once
        per ``VOXEL``."""
        for scan in self.memory.scans[self._taken:]:
            origins, directions, lengths = scan.perception.origins, scan.perception.directions, scan.perception.lengths
            if len(self._points):
                p = self._points
                along = directions @ p.T - np.sum(origins * directions, axis=1)[:, None]
                aside = (np.sum(p * p, axis=1)[None, :] - 2 * origins @ p.T
                         + np.sum(origins * origins, axis=1)[:, None] - along ** 2)
                through = (along > 0) & (along < lengths[:, None] - self.PASSED) & (aside < self.THROUGH ** 2)
                keep = ~through.any(axis=0)
                self._points, self._keys = self._points[keep], self._keys[keep]
            hit = lengths < self.ray_range
            points = origins[hit] + directions[hit] * lengths[hit, None]
            if len(points):
                keys, first = np.unique(cell_keys(points, VOXEL), return_index=True)
                new = ~np.isin(keys, self._keys)
                self._points = np.concatenate([self._points, points[first[new]]])
                self._keys = np.concatenate([self._keys, keys[new]])
        self._taken = len(self.memory.scans)
        return self._points

    @property
    def active(self) -> bool:
        """Whether a detour is being followed."""
        return self._path is not None

    def action(self, step: int, ee_pos: np.ndarray, goal: np.ndarray, tool_direction: np.ndarray,
               distances: Sequence[float]) -> np.ndarray | None:
        """The next step of the detour as an action (a translation, full step), or None to
        leave it to the policy. ``step``: the episode's step count; ``distances``: to the
        current goal after each step since it became current, oldest first."""
        d = self.detour
        if float(np.linalg.norm(goal - ee_pos)) < self.arrive:
            if self._path is not None:
                self._end(step)
            return None
        if self._path is None and (step - self._since < d.stall_steps
                                   or not stalled(distances, d.stall_steps, d.stall_gain)):
            return None
        if self._path is not None and self._last is not None:
            self._held = self._held + 1 if np.linalg.norm(ee_pos - self._last) < 1e-4 else 0
            if self._held >= d.held_steps:
                self._end(step)
                return None
        if self._path is None or step - self._planned_at >= d.replan_steps:
            self._path = self.plan(ee_pos, goal, tool_direction)
            self._planned_at = step
            if self._path is None:  # no way round: the policy acts, and may stall again
                self._end(step)
                return None
        near = np.linalg.norm(self._path - ee_pos, axis=1) < d.cell
        if near.any():
            self._path = self._path[int(np.nonzero(near)[0][-1]) + 1:]
        if not len(self._path):
            self._end(step)
            return None
        self._last = ee_pos.copy()
        offset = self._path[0] - ee_pos
        action = np.zeros(6, dtype=np.float32)
        action[:3] = offset / max(float(np.linalg.norm(offset)), 1e-9)
        return action

    def _end(self, step: int) -> None:
        self._path, self._since, self._last, self._held = None, step, None, 0

    def plan(self, start: np.ndarray, goal: np.ndarray, tool_direction: np.ndarray) -> np.ndarray | None:
        """Cell centres from next to ``start`` to within ``arrive`` of ``goal`` on which the
        tool keeps ``clearance`` from every remembered hit, or None if there is no such path."""
        d = self.detour
        lo = np.maximum(self.low, np.minimum(start, goal) - d.reach)
        hi = np.minimum(self.high, np.maximum(start, goal) + d.reach)
        shape = tuple(int(v) for v in np.floor((hi - lo) / d.cell) + 1)
        free = ~self._blocked(lo, shape, tool_direction)
        centres = np.stack(np.meshgrid(*[lo[i] + d.cell * np.arange(shape[i]) for i in range(3)], indexing="ij"), -1)
        # within the final approach's radius the final approach tests its own path, with its
        # own margin: a wall beside the goal must not make the goal unreachable here
        near = np.linalg.norm(centres - goal, axis=-1) < self.arrive - d.cell
        targets = near & free if (near & free).any() else near
        cost = _wavefront(targets, free | targets)
        # the tool may be within the clearance already (the shield holds it there): leave
        # from the free cell near it that is nearest the goal along the grid
        around = np.linalg.norm(centres - start, axis=-1)
        score = np.where(np.isfinite(cost) & (around < self.LEAVE), cost * d.cell + 2 * around, np.inf)
        if not np.isfinite(score.min()):
            return None
        cell = np.unravel_index(int(np.argmin(score)), shape)
        path = [centres[cell]]
        while cost[cell] > 0:
            cell = _downhill(cost, cell)
            path.append(centres[cell])
        return np.array(path)

    def _blocked(self, lo: np.ndarray, shape: tuple[int, ...], tool_direction: np.ndarray) -> np.ndarray:
        """Cells where a tip would bring the tool, pointing along ``tool_direction`` (and the
        arm ``behind`` it), within ``clearance`` of a remembered hit."""
        d = self.detour
        blocked = np.zeros(shape, dtype=bool)
        points = self.seen()
        if not len(points):
            return blocked
        # the tool runs from the tip back along -tool_direction: a tip at p + s * L * direction
        # puts the tool's point s across a hit at p
        length = self.tool_length + d.behind
        samples = np.linspace(0.0, 1.0, max(2, int(np.ceil(length / d.cell)) + 1))
        tips = (points[:, None, :] + samples[None, :, None] * length * np.asarray(tool_direction)).reshape(-1, 3)
        reach = d.clearance + self.tool_radius
        r = int(np.ceil(reach / d.cell))
        size = np.array(shape)
        cells = np.round((tips - lo) / d.cell).astype(np.int64) + r
        cells = cells[np.all((cells >= 0) & (cells < size + 2 * r), axis=1)]
        occupied = np.zeros(tuple(size + 2 * r), dtype=bool)
        occupied[cells[:, 0], cells[:, 1], cells[:, 2]] = True
        for o in np.ndindex(2 * r + 1, 2 * r + 1, 2 * r + 1):
            if np.linalg.norm(np.array(o) - r) * d.cell <= reach + d.cell / 2:
                blocked |= occupied[o[0]:o[0] + shape[0], o[1]:o[1] + shape[1], o[2]:o[2] + shape[2]]
        return blocked


def _wavefront(targets: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Steps from each free cell to the nearest target through free cells (26 neighbours),
    inf where none is reachable."""
    cost = np.full(free.shape, np.inf)
    cost[targets] = 0.0
    front = targets.copy()
    k = 0
    while front.any():
        k += 1
        grown = front.copy()
        for axis in range(3):
            shifted = grown.copy()
            lead = [slice(None)] * 3
            tail = [slice(None)] * 3
            lead[axis], tail[axis] = slice(1, None), slice(None, -1)
            shifted[tuple(lead)] |= grown[tuple(tail)]
            shifted[tuple(tail)] |= grown[tuple(lead)]
            grown = shifted
        front = grown & free & np.isinf(cost)
        cost[front] = k
    return cost


def _downhill(cost: np.ndarray, cell: tuple) -> tuple:
    """The neighbour of ``cell`` with the least cost (nearest in a tie)."""
    best, best_key = cell, (cost[cell], 0.0)
    for offset in np.ndindex(3, 3, 3):
        n = tuple(int(c + o - 1) for c, o in zip(cell, offset))
        if n == cell or any(v < 0 or v >= s for v, s in zip(n, cost.shape)):
            continue
        key = (cost[n], float(np.linalg.norm(np.array(offset) - 1)))
        if key < best_key:
            best, best_key = n, key
    return best
