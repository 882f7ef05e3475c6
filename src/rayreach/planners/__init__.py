"""Planners compared on the same scenes: the DRL policy and sampling planners in joint space.

``make_planner(name, robot)`` builds any of :data:`PLANNER_NAMES`; the executor
(:mod:`rayreach.evaluate.executor`) runs them all the same way.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from rayreach.acting.config import ActingConfig
from rayreach.planners.base import GlobalPlanner, ReactivePlanner, SamplingPlanner
from rayreach.planners.ncrrt import NCRRTConfig, ncrrt
from rayreach.planners.ompl_peer import OMPLConfig, ompl_available, ompl_plan
from rayreach.planners.result import PlanResult, Status
from rayreach.planners.rrt import RRTConfig, birrt, rrt
from rayreach.planners.smoothing import ShortcutConfig

SAMPLING_PLANNERS = ("rrt", "birrt", "ncrrt", "ompl-rrt", "ompl-rrtconnect")
DRL_PLANNERS = ("drl", "drl-alone", *(f"drl-no-{layer}" for layer in ActingConfig().layers))
"""``drl``: the policy with the shipped acting layers (``rayreach.acting``); ``drl-alone``:
with none, as the paper's agent acted; ``drl-no-LAYER``: every shipped layer but one (the
ablation; the slide, an option, is off in the stack already)."""
PLANNER_NAMES = (*DRL_PLANNERS, *SAMPLING_PLANNERS)


def drl_acting(name: str) -> ActingConfig:
    """The acting layers of DRL planner ``name`` (``DRL_PLANNERS``)."""
    if name == "drl":
        return ActingConfig()
    if name == "drl-alone":
        return ActingConfig.off()
    if name in DRL_PLANNERS and name.startswith("drl-no-"):
        return ActingConfig().without(name[len("drl-no-"):])
    raise ValueError(f"unknown DRL planner '{name}'; valid: {', '.join(DRL_PLANNERS)}")


def make_planner(name: str, robot: str, *, model: str | Path | None = None, time_limit: float | None = None,
                 smooth: bool = False, refuse_unseen: bool = True) -> GlobalPlanner | ReactivePlanner:
    """Planner ``name`` for ``robot`` with its defaults; ``time_limit`` (s) for sampling
    planners, ``model`` for the DRL planner (default: the shipped policy), which refuses a
    query outside its training workspace unless ``refuse_unseen`` is False."""
    if name in DRL_PLANNERS:
        from rayreach.planners.drl import DRLPlanner, shipped_model

        planner = DRLPlanner(model if model is not None else shipped_model(robot), acting=drl_acting(name), name=name,
                             refuse_unseen=refuse_unseen)
        if planner.robot != robot:
            raise ValueError(f"model {model} is a {planner.robot} policy, not {robot}")
        return planner
    algorithms = {
        "rrt": (rrt, RRTConfig()),
        "birrt": (birrt, RRTConfig(goal_bias=0.0)),  # RRT-Connect has no goal bias
        "ncrrt": (ncrrt, NCRRTConfig()),
        "ompl-rrt": (ompl_plan, OMPLConfig(algorithm="RRT")),
        "ompl-rrtconnect": (ompl_plan, OMPLConfig(algorithm="RRTConnect")),
    }
    if name not in algorithms:
        raise ValueError(f"unknown planner '{name}'; valid: {', '.join(PLANNER_NAMES)}")
    if name.startswith("ompl") and not ompl_available():
        raise ImportError(f"planner '{name}' needs OMPL: pip install 'rayreach[ompl]'")
    algorithm, settings = algorithms[name]
    if time_limit is not None:
        settings = replace(settings, time_limit=float(time_limit))
    return SamplingPlanner(name, algorithm, settings, ShortcutConfig() if smooth else None)


__all__ = ["DRL_PLANNERS", "PLANNER_NAMES", "SAMPLING_PLANNERS", "GlobalPlanner", "PlanResult", "ReactivePlanner", "Status",
           "make_planner"]
