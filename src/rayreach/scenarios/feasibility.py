"""Checks that make a scenario usable: start and goals reachable (IK), start collision-free."""

from __future__ import annotations

from typing import Iterator, Sequence

import numpy as np

from rayreach.sim.kinematics import IKParams, Kinematics
from rayreach.scenarios.schema import Scenario, ScenarioError
from rayreach.sim.scene import Scene
from rayreach.sim.transforms import rpy_to_matrix

REACH_TOLERANCE = 1e-4
"""IK position accuracy (m) for a start or goal to count as reachable."""
_REACH_IK = IKParams(tolerance=REACH_TOLERANCE, max_iterations=200)


def random_seed(kin: Kinematics, rng: np.random.Generator) -> np.ndarray:
    """A random configuration within the joint limits (clipped to +-pi), to seed IK from."""
    return rng.uniform(np.maximum(kin.lower, -np.pi), np.minimum(kin.upper, np.pi))


def ik_seeds(kin: Kinematics, first: Sequence[float], n_random: int, rng: np.random.Generator) -> list[np.ndarray]:
    """The given seed, then random configurations within the joint limits (clipped to +-pi)."""
    return [np.asarray(first, dtype=float)] + [random_seed(kin, rng) for _ in range(n_random)]


def solve_start(scenario: Scenario, kin: Kinematics, n_random_seeds: int = 8) -> np.ndarray:
    """The start configuration: given joints, or IK of the start pose seeded from home."""
    spec = kin.spec
    if scenario.start.joints is not None:
        q = np.asarray(scenario.start.joints, dtype=float)
        bad = [spec.joint_names[i] for i in range(6) if not kin.lower[i] <= q[i] <= kin.upper[i]]
        if bad:
            raise ScenarioError(f"{scenario.name}.start.joints: {bad} outside the joint limits of {spec.name}")
        return q
    assert scenario.start.position is not None and scenario.start.rpy is not None
    target = np.asarray(scenario.start.position, dtype=float)
    rot = rpy_to_matrix(scenario.start.rpy)
    rng = np.random.default_rng(0)  # fixed: a scenario always resolves to the same start
    for seed in ik_seeds(kin, spec.home, n_random_seeds, rng):
        result = kin.ik(target, rot, seed, _REACH_IK)
        if result.converged:
            return result.q
    raise ScenarioError(
        f"{scenario.name}.start: pose {list(scenario.start.position)} rpy {list(scenario.start.rpy)} "
        f"is unreachable for {spec.name} (IK did not converge from {n_random_seeds + 1} seeds)"
    )


def goal_solutions(
    kin: Kinematics, goal: Sequence[float], q_seed: np.ndarray, rng: np.random.Generator, n_random_seeds: int = 8,
    more_rng: np.random.Generator | None = None, n_more_seeds: int = 0,
) -> Iterator[np.ndarray]:
    """Configurations whose tool tip is at ``goal`` (position only), one per converged seed,
    in seed order (``q_seed`` first).

    After the ``n_random_seeds`` of ``rng``, ``n_more_seeds`` further random seeds come from
    ``more_rng``, drawn one at a time: a caller that stops at the first usable solution pays
    for them only when the first seeds gave none, and those first seeds stay the same
    whatever ``n_more_seeds`` is."""
    target = np.asarray(goal, dtype=float)
    for seed in ik_seeds(kin, q_seed, n_random_seeds, rng):
        result = kin.ik(target, None, seed, _REACH_IK)
        if result.converged:
            yield result.q
    if more_rng is None:
        return
    for _ in range(n_more_seeds):
        result = kin.ik(target, None, random_seed(kin, more_rng), _REACH_IK)
        if result.converged:
            yield result.q


def goal_configuration(
    kin: Kinematics, goal: Sequence[float], q_seed: np.ndarray, rng: np.random.Generator, n_random_seeds: int = 8
) -> np.ndarray | None:
    """The first of :func:`goal_solutions`, or None."""
    return next(goal_solutions(kin, goal, q_seed, rng, n_random_seeds), None)


def validate(scenario: Scenario, kin: Kinematics, scene: Scene, q_start: np.ndarray) -> None:
    """Raise :class:`ScenarioError` if a goal is unreachable or an obstacle overlaps the start.

    ``scene`` must hold the scenario's obstacles at time 0.
    """
    rng = np.random.default_rng(0)
    for i, goal in enumerate(scenario.goals):
        if goal_configuration(kin, goal, q_start, rng) is None:
            raise ScenarioError(f"{scenario.name}.goals[{i}]: {list(goal)} is unreachable for {kin.spec.name}")
    scene.set_joints(q_start)
    hits = scene.colliding_obstacles()
    if hits:
        names = [scenario.obstacles[i].name or f"obstacles[{i}]" for i in hits]
        raise ScenarioError(f"{scenario.name}: {', '.join(names)} overlap(s) the robot at its start configuration")
    start_ee = kin.fk(q_start)[:3, 3]
    if not scenario.in_workspace(start_ee):
        raise ScenarioError(
            f"{scenario.name}.start: the end effector starts at {np.round(start_ee, 3).tolist()}, "
            f"outside the workspace {list(scenario.workspace_low)} .. {list(scenario.workspace_high)}"
        )
