"""OMPL's RRT and RRTConnect (``pip install rayreach[ompl]``) on rayreach's collision checker.

The planners a user would otherwise reach for, run on the same query, validity checker,
edge resolution and time limit as rayreach's own, so the comparison is about the algorithm.
Uses the 2.x bindings: states from ``space.allocState()`` indexed ``s[i]``, a plain Python
callable as validity checker.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from rayreach.planners.collision import CollisionChecker, finish_with_recheck, refuse_endpoints, sampling_box
from rayreach.planners.result import PlanResult, Status

OMPL_PLANNERS = ("RRT", "RRTConnect")


def ompl_available() -> bool:
    try:
        import ompl  # noqa: F401
    except ImportError:
        return False
    return True


@dataclass(frozen=True)
class OMPLConfig:
    algorithm: str = "RRTConnect"
    """``RRT`` or ``RRTConnect`` (OMPL class names)."""
    step_size: float = 0.4
    """OMPL's ``range``; OMPL measures it as the Euclidean joint distance, rad."""
    goal_bias: float = 0.05
    """RRT only; OMPL's default."""
    resolution: float = 0.02
    """Edge check resolution, rad (converted to OMPL's fraction of the space's extent)."""
    sampling_margin: float | None = 1.0
    """Bounds of the state space: the same start-goal box as rayreach's planners (None: the
    joint limits)."""
    time_limit: float = 30.0


def ompl_plan(start: np.ndarray, goal: np.ndarray, checker: CollisionChecker, rng: np.random.Generator,
              config: OMPLConfig = OMPLConfig()) -> PlanResult:
    """Plan with OMPL; OMPL's global random generator is seeded from ``rng`` first, so equal
    seeds give equal paths when the run is not cut by the time limit."""
    if config.algorithm not in OMPL_PLANNERS:
        raise ValueError(f"unknown OMPL planner '{config.algorithm}'; valid: {', '.join(OMPL_PLANNERS)}")
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou

    record = {"planner": f"ompl-{config.algorithm.lower()}", **asdict(config)}
    t0 = time.perf_counter()
    refused = refuse_endpoints(checker, start, goal, record, t0)
    if refused is not None:
        return refused

    ou.setLogLevel(ou.LOG_NONE)
    ou.RNG.setSeed(int(rng.integers(1, 2**31 - 1)))
    dof = len(start)
    space = ob.RealVectorStateSpace(dof)
    low, high = sampling_box(checker, start, goal, config.sampling_margin)
    bounds = ob.RealVectorBounds(dof)
    for i in range(dof):
        bounds.setLow(i, float(low[i]))
        bounds.setHigh(i, float(high[i]))
    space.setBounds(bounds)
    setup = og.SimpleSetup(space)
    q = np.empty(dof)

    def valid(state) -> bool:
        for i in range(dof):
            q[i] = state[i]
        return checker.valid(q)

    setup.setStateValidityChecker(valid)
    s_start, s_goal = space.allocState(), space.allocState()
    for i in range(dof):
        s_start[i], s_goal[i] = float(start[i]), float(goal[i])
    setup.setStartAndGoalStates(s_start, s_goal)
    info = setup.getSpaceInformation()
    # OMPL spaces edge checks by Euclidean length and at other points than the shared re-check;
    # checking at half the resolution keeps paths that pass OMPL but fail the re-check rare.
    info.setStateValidityCheckingResolution(0.5 * config.resolution / space.getMaximumExtent())
    planner = getattr(og, config.algorithm)(info)
    planner.setRange(config.step_size)
    if config.algorithm == "RRT":
        planner.setGoalBias(config.goal_bias)
    setup.setPlanner(planner)
    status = setup.solve(config.time_limit)
    elapsed = time.perf_counter() - t0
    if not setup.haveExactSolutionPath():
        setup.clear()
        return PlanResult(Status.TIMEOUT, None, elapsed, 0, record,
                          f"OMPL {config.algorithm}: {status} within {config.time_limit} s")
    solution = setup.getSolutionPath()
    path = [np.array([solution.getState(k)[i] for i in range(dof)]) for k in range(solution.getStateCount())]
    setup.clear()
    path[0], path[-1] = start.copy(), goal.copy()  # OMPL copies states as float; keep the exact query
    return finish_with_recheck(path, checker, config.resolution, record, elapsed)
