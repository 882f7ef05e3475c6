"""``rayreach.plan``: one planning query, planned and executed in simulation, from Python.

It is the executor that ``rayreach evaluate`` runs (:class:`rayreach.evaluate.executor.Executor`)
behind one call, so a result from here is a result the paper's table would count::

    import rayreach

    outcome = rayreach.plan("exp1", planner="drl", seed=0)
    print(outcome.status, outcome.path_length, outcome.joint_path.shape)

A scene can be built in code::

    import math
    from rayreach.scenarios import ObstacleSpec, Scenario, StartSpec

    plate = ObstacleSpec("box", position=(0.0, 0.45, 0.3), half_extents=(0.002, 0.12, 0.05))
    scene = Scenario(name="plate", robot="ur5", goals=((-0.15, 0.45, 0.3),), obstacles=(plate,),
                     start=StartSpec(position=(0.15, 0.45, 0.3), rpy=(math.pi, 0.0, math.pi)),
                     workspace_low=(-0.4, 0.3, 0.2), workspace_high=(0.4, 0.7, 0.5))
    rayreach.plan(scene, planner="ompl-rrtconnect")
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from rayreach.scenarios import WORLD_SUITES, Scenario, get_scenario
from rayreach.scenarios.schema import scenario_from_dict

STATUSES = ("success", "collision", "timeout", "out of bounds", "no plan", "outside training")
"""What a query can end in, as the executor records it (``RunRecord.outcome``): ``success``
(every goal reached within the tolerance, no contact); ``collision`` (the arm touched an
obstacle); ``timeout`` (a DRL planner used up its step budget); ``out of bounds`` (a DRL
planner left the workspace); ``no plan`` (a sampling planner found no path, or no
collision-free goal configuration; ``record.plan_status`` and ``record.message`` say which);
``outside training`` (a DRL planner refused a start or goal outside the workspace its policy
was trained in; ``record.message`` names the point and the box)."""


@dataclass(frozen=True)
class PlanOutcome:
    """One executed query. Arrays hold one row per control step, the start first; after
    ``no plan`` nothing moved and they are empty."""

    status: str
    """One of :data:`STATUSES`."""
    joint_path: np.ndarray
    """Joint angles of the executed motion, rad (T x 6)."""
    times: np.ndarray
    """Time of each row from the start, s (T; the control period apart)."""
    ee_path: np.ndarray
    """Tool-tip positions, world frame, m (T x 3)."""
    path_length: float
    """Length of ``ee_path`` as a polyline, m (NaN after ``no plan``)."""
    planning_time: float
    """Seconds spent planning: goal IK and search for a sampling planner; choosing every
    action (with stepping the simulation) for a DRL planner."""
    record: Any
    """The executor's full :class:`~rayreach.evaluate.executor.RunRecord` (config, acting share, ...)."""

    @property
    def success(self) -> bool:
        return self.status == "success"


def as_scenario(scene: str | Path | Mapping[str, Any] | Scenario) -> str | Scenario:
    """``scene`` in a form the executor takes: a dict is validated as a scene file is (same
    messages, the source called ``scene``); a name of drawn worlds (``random``) stays a name."""
    if isinstance(scene, Mapping):
        return scenario_from_dict(dict(scene), source="scene")
    if isinstance(scene, str) and scene in WORLD_SUITES:
        return scene
    if isinstance(scene, (str, Path, Scenario)):
        return get_scenario(scene)
    raise TypeError(f"scene: expected a name (exp1..exp7), a scene-file path, a dict or a Scenario, "
                    f"got {type(scene).__name__}")


def plan(scene: str | Path | Mapping[str, Any] | Scenario, planner: str = "drl", seed: int = 0, *,
         model: str | Path | None = None, robot: str | None = None, time_limit: float | None = None,
         smooth: bool = False, goal_tolerance: float = 0.01, replan: bool = False,
         refuse_unseen: bool = True) -> PlanOutcome:
    """Plan and execute one query of ``scene`` with ``planner`` (any of
    ``rayreach.planners.PLANNER_NAMES``), its randomness from ``seed``.

    :param scene: a built-in experiment (``"exp1"``), a scene-file path, a dict with the
        scene file's fields, or a :class:`~rayreach.scenarios.Scenario`; ``"random"`` with
        ``robot`` is training-like world ``seed``.
    :param model: DRL planners' policy, a robot name (``"ur5"``: the shipped one, the
        default) or a model ``.zip`` path.
    :param robot: only for drawn worlds; a scene names its robot.
    :param time_limit: sampling planners' planning budget, s (default: the planner's).
    :param smooth: shortcut-smooth a sampling planner's path before executing it.
    :param goal_tolerance: success radius around each goal, m (the paper's 0.01).
    :param replan: sampling planners replan when the remaining path becomes invalid.
    :param refuse_unseen: DRL planners answer ``"outside training"`` for a start or goal
        outside the workspace their policy was trained in; False runs the policy anyway.
    :raises ValueError: an unknown planner (the message lists the valid ones), an unknown
        scene name or a bad scene dict (``ScenarioError``, naming the field)."""
    from rayreach.evaluate.executor import ExecutionConfig, Executor
    from rayreach.planners import PLANNER_NAMES, make_planner

    if planner not in PLANNER_NAMES:
        raise ValueError(f"unknown planner '{planner}'; valid: {', '.join(PLANNER_NAMES)}")
    config = ExecutionConfig(goal_tolerance=goal_tolerance, replan=replan)
    with Executor(as_scenario(scene), robot=robot, config=config) as executor:
        built = make_planner(planner, executor.robot, model=model, time_limit=time_limit, smooth=smooth,
                             refuse_unseen=refuse_unseen)
        record = executor.run(built, seed)
        period = executor.period
    joint_path = np.asarray(record.joint_path, dtype=float)
    ee_path = np.asarray(record.ee_path, dtype=float)
    return PlanOutcome(status=record.outcome, joint_path=joint_path, ee_path=ee_path,
                       times=np.arange(len(joint_path)) * period, path_length=float(record.path_length),
                       planning_time=float(record.planning_time), record=record)


__all__ = ["STATUSES", "PlanOutcome", "as_scenario", "plan"]
