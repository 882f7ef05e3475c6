"""RRT and bidirectional RRT (RRT-Connect) in joint space.

Both are plain functions of a start, a goal configuration, a :class:`CollisionChecker` and a
random generator, and return a :class:`PlanResult`; they never return a path they did not
find, and every returned path is re-checked edge by edge before it counts.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from rayreach.planners.collision import CollisionChecker, finish_with_recheck, refuse_endpoints, sampling_box
from rayreach.planners.result import PlanResult, Status


@dataclass(frozen=True)
class RRTConfig:
    step_size: float = 0.4
    """Largest joint-space extension per new node (max-norm over joints), rad."""
    sampling_margin: float | None = 1.0
    """Random samples come from the box spanned by start and goal, widened by this many rad
    per joint (within the limits); None samples the whole joint range, which for the UR5's
    +-2 pi joints timed out on exp1 in 9 of 10 seeds (5 s limit)."""
    goal_bias: float = 0.35
    """Probability of sampling the goal instead of a random configuration (RRT only; 0.35 as
    in the paper's code base, which called pybullet-planning's rrt)."""
    resolution: float = 0.02
    """Edge collision-check resolution, rad per joint."""
    time_limit: float = 30.0
    """Seconds of planning before giving up with status timeout."""
    max_iterations: int = 1_000_000


class Tree:
    """Nodes in a growing array (fast nearest-neighbour by brute force) with parent links."""

    def __init__(self, root: np.ndarray, capacity: int = 1024) -> None:
        self.nodes = np.empty((capacity, len(root)))
        self.nodes[0] = root
        self.parents = [-1]
        self.size = 1

    def nearest(self, q: np.ndarray, allowed: np.ndarray | None = None) -> int:
        """Index of the node closest to ``q``, among nodes where ``allowed`` is true if given."""
        diff = self.nodes[: self.size] - q
        d2 = np.einsum("ij,ij->i", diff, diff)
        if allowed is not None:
            d2 = np.where(allowed, d2, np.inf)
        return int(np.argmin(d2))

    def add(self, q: np.ndarray, parent: int) -> int:
        if self.size == len(self.nodes):
            self.nodes = np.concatenate((self.nodes, np.empty_like(self.nodes)))
        self.nodes[self.size] = q
        self.parents.append(parent)
        self.size += 1
        return self.size - 1

    def path_to(self, index: int) -> list[np.ndarray]:
        """Root to node ``index``."""
        out = []
        while index >= 0:
            out.append(self.nodes[index].copy())
            index = self.parents[index]
        return out[::-1]


def steer(q_from: np.ndarray, q_to: np.ndarray, step: float) -> np.ndarray:
    diff = q_to - q_from
    largest = float(np.max(np.abs(diff)))
    return q_to.copy() if largest <= step else q_from + diff * (step / largest)


def finish(path: list[np.ndarray] | None, checker: CollisionChecker, config: RRTConfig, t0: float,
            iterations: int, name: str) -> PlanResult:
    elapsed = time.perf_counter() - t0
    record = {"planner": name, **asdict(config)}
    if path is None:
        return PlanResult(Status.TIMEOUT, None, elapsed, iterations, record,
                          f"no path within {config.time_limit} s / {iterations} iterations")
    return finish_with_recheck(path, checker, config.resolution, record, elapsed, iterations)


def rrt(start: np.ndarray, goal: np.ndarray, checker: CollisionChecker, rng: np.random.Generator,
        config: RRTConfig = RRTConfig()) -> PlanResult:
    """Goal-biased RRT from ``start``; solved once an edge reaches ``goal`` exactly."""
    t0 = time.perf_counter()
    refused = refuse_endpoints(checker, start, goal, {"planner": "rrt", **asdict(config)}, t0)
    if refused is not None:
        return refused
    tree = Tree(start)
    low, high = sampling_box(checker, start, goal, config.sampling_margin)
    iterations = 0
    while iterations < config.max_iterations and time.perf_counter() - t0 < config.time_limit:
        iterations += 1
        sample = goal if rng.random() < config.goal_bias else rng.uniform(low, high)
        near = tree.nearest(sample)
        new = steer(tree.nodes[near], sample, config.step_size)
        if not checker.valid(new) or not checker.edge_valid(tree.nodes[near], new, config.resolution):
            continue
        index = tree.add(new, near)
        if np.array_equal(new, goal):
            return finish(tree.path_to(index), checker, config, t0, iterations, "rrt")
    return finish(None, checker, config, t0, iterations, "rrt")


def connect(tree: Tree, target: np.ndarray, checker: CollisionChecker, config: RRTConfig) -> tuple[int, bool]:
    """Greedy extension of ``tree`` towards ``target``: (last node added or nearest, reached)."""
    index = tree.nearest(target)
    while True:
        current = tree.nodes[index]
        new = steer(current, target, config.step_size)
        if not checker.valid(new) or not checker.edge_valid(current, new, config.resolution):
            return index, False
        index = tree.add(new, index)
        if np.array_equal(new, target):
            return index, True


def birrt(start: np.ndarray, goal: np.ndarray, checker: CollisionChecker, rng: np.random.Generator,
          config: RRTConfig = RRTConfig()) -> PlanResult:
    """Bidirectional RRT (RRT-Connect): trees from start and goal take turns growing one step
    towards a random sample, and the other tree then greedily connects to the new node."""
    t0 = time.perf_counter()
    refused = refuse_endpoints(checker, start, goal, {"planner": "birrt", **asdict(config)}, t0)
    if refused is not None:
        return refused
    trees = [Tree(start), Tree(goal)]
    low, high = sampling_box(checker, start, goal, config.sampling_margin)
    iterations = 0
    while iterations < config.max_iterations and time.perf_counter() - t0 < config.time_limit:
        iterations += 1
        grow, other = trees[(iterations - 1) % 2], trees[iterations % 2]
        sample = rng.uniform(low, high)
        near = grow.nearest(sample)
        new = steer(grow.nodes[near], sample, config.step_size)
        if not checker.valid(new) or not checker.edge_valid(grow.nodes[near], new, config.resolution):
            continue
        added = grow.add(new, near)
        joined, reached = connect(other, new, checker, config)
        if reached:
            a, b = grow.path_to(added), other.path_to(joined)
            path = a + b[::-1][1:] if grow is trees[0] else b + a[::-1][1:]
            return finish(path, checker, config, t0, iterations, "birrt")
    return finish(None, checker, config, t0, iterations, "birrt")
