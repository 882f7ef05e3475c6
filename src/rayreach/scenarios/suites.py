"""The suites of drawn worlds: ``random`` (the training worlds) and ``broad`` (a user's cell).

An environment or an evaluation names a suite where it would name a scene; each world of it
is drawn at reset from the reset's seed. This module gives the suite's sampler and workspace.
"""

from __future__ import annotations

import numpy as np

from rayreach.robots.spec import RobotSpec
from rayreach.scenarios import BROAD, RANDOM, Scenario, check_suite
from rayreach.scenarios.broad_world import BroadWorldConfig, BroadWorlds, broad_kinds, broad_workspace
from rayreach.scenarios.random_world import RandomWorldConfig, RandomWorlds, WorldChecker, world_kinds
from rayreach.sim.kinematics import Kinematics


def world_sampler(suite: str, kin: Kinematics, checker: WorldChecker,
                  config: RandomWorldConfig) -> RandomWorlds | BroadWorlds:
    """The sampler of ``suite``'s worlds, checked in ``checker``; the broad worlds take the
    counts, distances and clearance of ``config`` (their kinds are their own)."""
    if check_suite(suite) == RANDOM:
        return RandomWorlds(kin, checker, config)
    return BroadWorlds(kin, checker, BroadWorldConfig(
        n_obstacles=config.n_obstacles, min_goal_distance=config.min_goal_distance, margin=config.margin,
        start_clearance=config.start_clearance, max_tries=config.max_tries))


def suite_workspace(suite: str, spec: RobotSpec) -> tuple[np.ndarray, np.ndarray]:
    """The workspace box of ``suite``'s worlds: the robot's training box, or its reach (broad)."""
    if check_suite(suite) == BROAD:
        return broad_workspace(spec)
    return np.asarray(spec.workspace_low, dtype=float), np.asarray(spec.workspace_high, dtype=float)


def suite_kinds(suite: str, scenario: Scenario) -> list[str]:
    """The kinds of the elements a world of ``suite`` drew (``world_kinds``, ``broad_kinds``)."""
    return broad_kinds(scenario) if check_suite(suite) == BROAD else world_kinds(scenario)
