"""NC-RRT: the paper's "modified bidirectional RRT" with Wang et al.'s node control (2020).

Two trees, from the start and from the goal, take turns growing one step (same rate) and the
other tree then greedily connects to the new node, as in RRT-Connect. Each tree adds the two
mechanisms of Wang et al.'s NC-RRT:

- **Gradually changing sampling area.** A tree samples only inside a ball around the other
  tree's root (its target) of radius R. R starts large enough to hold the whole sampling
  box; a successful extension sets R to the new node's distance from the target (the area
  closes in), a failed one widens it by ``growth * step_size`` (the area opens up again).
- **Node control.** Every node counts its failed extensions; a node whose count has reached
  the node control factor is no longer extended, so trees grow from their boundary instead of
  retrying nodes stuck at an obstacle ("local traps"). When every node is excluded, the factor
  rises by one.

Where the publication is silent (the values of the growth coefficient and the control factor,
what exactly is counted, how the factor changes) the choices are documented in
``docs/planners.md``.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from rayreach.planners.collision import CollisionChecker, refuse_endpoints, sampling_box
from rayreach.planners.result import PlanResult
from rayreach.planners.rrt import RRTConfig, Tree, connect, finish, steer


@dataclass(frozen=True)
class NCRRTConfig(RRTConfig):
    goal_bias: float = 0.0
    """Unused: the shrinking sampling ball does the goal biasing."""
    growth: float = 2.0
    """Growth coefficient k: a failed extension widens the sampling ball by k * step_size."""
    node_control: int = 3
    """Initial node control factor: failed extensions after which a node is excluded."""


class ControlledTree(Tree):
    """A tree whose nodes count their failed extensions."""

    def __init__(self, root: np.ndarray, capacity: int = 1024) -> None:
        super().__init__(root, capacity)
        self.failures = np.zeros(capacity, dtype=int)

    def add(self, q: np.ndarray, parent: int) -> int:
        index = super().add(q, parent)
        if index >= len(self.failures):
            self.failures = np.concatenate((self.failures, np.zeros_like(self.failures)))
        self.failures[index] = 0
        return index

    def allowed(self, control: int) -> np.ndarray:
        return self.failures[: self.size] < control


@dataclass
class SamplingBall:
    """Uniform samples from the ball of radius ``radius`` around ``centre``, within a box."""

    centre: np.ndarray
    radius: float
    low: np.ndarray
    high: np.ndarray

    def sample(self, rng: np.random.Generator, tries: int = 100) -> np.ndarray:
        dim = len(self.centre)
        box_diagonal = float(np.linalg.norm(self.high - self.low))
        for _ in range(tries):
            if self.radius >= box_diagonal / 2:  # the ball covers most of the box: draw from the box
                q = rng.uniform(self.low, self.high)
                if np.linalg.norm(q - self.centre) <= self.radius:
                    return q
            else:  # draw from the ball, keep what lies in the box
                direction = rng.normal(size=dim)
                direction /= np.linalg.norm(direction)
                q = self.centre + direction * self.radius * rng.random() ** (1.0 / dim)
                if np.all(q >= self.low) and np.all(q <= self.high):
                    return q
        return rng.uniform(self.low, self.high)


def ncrrt(start: np.ndarray, goal: np.ndarray, checker: CollisionChecker, rng: np.random.Generator,
          config: NCRRTConfig = NCRRTConfig()) -> PlanResult:
    """Bidirectional NC-RRT from ``start`` to ``goal``; see the module docstring."""
    t0 = time.perf_counter()
    refused = refuse_endpoints(checker, start, goal, {"planner": "ncrrt", **asdict(config)}, t0)
    if refused is not None:
        return refused
    low, high = sampling_box(checker, start, goal, config.sampling_margin)
    trees = [ControlledTree(start), ControlledTree(goal)]
    farthest = float(np.linalg.norm(high - low))
    balls = [SamplingBall(goal, farthest, low, high), SamplingBall(start, farthest, low, high)]
    control = [config.node_control, config.node_control]
    iterations = 0
    while iterations < config.max_iterations and time.perf_counter() - t0 < config.time_limit:
        iterations += 1
        side = (iterations - 1) % 2
        grow, other, ball = trees[side], trees[1 - side], balls[side]
        allowed = grow.allowed(control[side])
        if not allowed.any():
            control[side] += 1
            continue
        sample = ball.sample(rng)
        near = grow.nearest(sample, allowed)
        new = steer(grow.nodes[near], sample, config.step_size)
        if not checker.valid(new) or not checker.edge_valid(grow.nodes[near], new, config.resolution):
            grow.failures[near] += 1
            ball.radius = min(ball.radius + config.growth * config.step_size, farthest)
            continue
        added = grow.add(new, near)
        ball.radius = float(np.linalg.norm(new - ball.centre))
        joined, reached = connect(other, new, checker, config)
        if reached:
            a, b = grow.path_to(added), other.path_to(joined)
            path = a + b[::-1][1:] if side == 0 else b + a[::-1][1:]
            return finish(path, checker, config, t0, iterations, "ncrrt")
    return finish(None, checker, config, t0, iterations, "ncrrt")
