"""exp1's UR5 with obstacles (and a goal) placed around the tool point it starts at, for
tests that need something at a known distance from the tool; and the acting layers round it."""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Sequence

import numpy as np

from rayreach.acting import ActingConfig, ActingEnv
from rayreach.acting.detour import Detour
from rayreach.acting.final_approach import FinalApproach
from rayreach.acting.shield import ACTING_SAFETY, SLIDE, SafetyLayer
from rayreach.env.reach import ReachEnv
from rayreach.scenarios import get_scenario
from rayreach.scenarios.schema import ObstacleSpec


def exp1_around_the_tool(obstacles: Sequence[Callable[[np.ndarray], ObstacleSpec]],
                         goal_offset: np.ndarray | None = None, **env_options: Any) -> ReachEnv:
    """exp1 with ``obstacles`` (each a function of the start's tool point) instead of its
    plate, and the goal ``goal_offset`` from that point (exp1's own goal if None)."""
    scenario = get_scenario("exp1")
    probe = ReachEnv(robot="ur5", scenario=scenario)
    _, info = probe.reset(seed=0)
    probe.close()
    ee = np.asarray(info["ee_position"])
    goals = scenario.goals if goal_offset is None else (tuple(ee + goal_offset),)
    scenario = dataclasses.replace(scenario, goals=goals, obstacles=tuple(make(ee) for make in obstacles))
    return ReachEnv(robot="ur5", scenario=scenario, **env_options)


SLIDING = dataclasses.replace(ACTING_SAFETY, slide=SLIDE)
"""The shipped safety layer with the slide asked for (an option, off in the shipped stack)."""
SLIDING_STACK = ActingConfig(safety=SLIDING)
"""The shipped stack with the slide: every layer of ``rayreach.acting.LAYERS`` on."""


def layers(final_approach: FinalApproach | None = None, safety: SafetyLayer = SafetyLayer(),
           detour: Detour | None = None) -> ActingConfig:
    """The acting layers given and no others (every one off by default)."""
    return ActingConfig(final_approach=final_approach, safety=safety, detour=detour, resample=False)


def acting_around_the_tool(obstacles: Sequence[Callable[[np.ndarray], ObstacleSpec]], config: ActingConfig,
                           goal_offset: np.ndarray | None = None, **env_options: Any) -> ActingEnv:
    """``exp1_around_the_tool``'s scene acting through the layers of ``config``."""
    return ActingEnv(exp1_around_the_tool(obstacles, goal_offset, **env_options), config)
