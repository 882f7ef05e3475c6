"""The paper's planner: a trained PPO policy acting on rays and robot state, step by step."""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from rayreach.acting.config import ActingConfig
from rayreach.acting.resample import ActingPolicy
from rayreach.learning.policy import load_policy
from rayreach.planners.base import ReactivePlanner

MODELS_DIR = Path(str(resources.files("rayreach.models")))
"""The shipped policies (``<robot>.zip`` with ``<robot>.json`` beside it): package data of
``rayreach.models``, so an installed wheel has them; in a checkout, the repository's ``models/``."""


def shipped_model(robot: str) -> Path:
    """The shipped policy for ``robot``; the error names the robots that have one."""
    candidate = MODELS_DIR / f"{robot}.zip"
    if candidate.is_file():
        return candidate
    raise FileNotFoundError(
        f"no shipped policy for '{robot}'; shipped: {', '.join(shipped_robots()) or 'none'}; "
        "pass a model path instead (a checkpoint.zip or an exported bundle)"
    )


def shipped_robots() -> tuple[str, ...]:
    """The robots with a shipped policy, in ``rayreach.robots.ROBOTS`` order."""
    from rayreach.robots import ROBOTS

    return tuple(name for name in ROBOTS if (MODELS_DIR / f"{name}.zip").is_file())


def resolve_model(name_or_path: str | Path) -> Path:
    """A policy given as a robot name (``ur5``: its shipped policy) or as a file path.

    Every option that takes a policy goes through here, so a name works wherever a path
    does. An existing file wins over a name; a missing path (``.zip`` or with a folder) is
    returned as it is, for the loader to name the missing file."""
    path = Path(name_or_path)
    if path.is_file():
        return path
    from rayreach.robots import ROBOTS

    name = str(name_or_path).lower()
    if name in ROBOTS:
        return shipped_model(name)
    if path.suffix == ".zip" or len(path.parts) > 1:
        return path
    raise FileNotFoundError(
        f"no shipped policy for '{name_or_path}' and no such file; robots with a shipped policy: "
        f"{', '.join(shipped_robots())}; or give a path to a model .zip"
    )


UNSEEN_MARGIN = 0.05
"""How far (m) a start or goal may lie outside the training workspace before the DRL planner
refuses the query."""


class DRLPlanner(ReactivePlanner):
    """The trained policy acting through ``acting`` (``ActingConfig.off()``, planner
    ``drl-alone``: the policy itself, as the paper's agent acted).

    The policy was trained only in its robot's training workspace, the box
    ``RobotSpec.workspace_low`` .. ``workspace_high`` (world frame, robot at its default base;
    UR5: x -0.4..0.4, y 0.3..0.7, z 0.2..0.5 m; KR16: x -0.8..0.8, y -0.4..0.8, z 0.4..1.8 m),
    among the obstacle kinds of its training worlds; a policy trained in broad worlds
    (``TrainConfig.suite``), in the box of the arm's reach. Outside that box its actions are
    guesses: it times out or wanders. So with ``refuse_unseen`` (the default) a query whose
    start or any goal lies more than ``unseen_margin`` outside the box is refused before the
    arm moves, recorded as ``outside training`` with a message naming the point and the box;
    a sampling planner (``rrt``, ``birrt``, ``ncrrt``, ``ompl-rrtconnect``) can plan such a
    scene. ``refuse_unseen=False`` runs the policy there anyway. A user's scene should keep
    its start and goals inside the box (moving the scene, or the robot's base, to fit)."""

    def __init__(self, model: str | Path, deterministic: bool = True, acting: ActingConfig = ActingConfig(),
                 name: str = "drl", refuse_unseen: bool = True, unseen_margin: float = UNSEEN_MARGIN) -> None:
        self.policy = load_policy(resolve_model(model))
        self.deterministic = deterministic
        self.acting = acting
        self.name = name
        self.refuse_unseen = refuse_unseen
        self.unseen_margin = unseen_margin
        self.observation = self.policy.observation
        self._acting = ActingPolicy.acting(self.policy, acting, deterministic)

    @property
    def robot(self) -> str:
        return self.policy.robot

    def reset(self, seed: int) -> None:
        self._acting.reset(seed)

    def act(self, observation: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        return self._acting.act(observation, info)

    def refusal(self, start: np.ndarray, goals: np.ndarray) -> str | None:
        """Why the policy will not run a query from tool position ``start`` to ``goals``
        (world frame, m): the first point outside its training workspace by more than the
        margin; None when it will (or ``refuse_unseen`` is off)."""
        if not self.refuse_unseen:
            return None
        from rayreach.robots import get_robot
        from rayreach.scenarios.suites import suite_workspace

        spec = get_robot(self.robot)
        low, high = suite_workspace(self.policy.suite, spec)
        points = [("start", np.asarray(start, dtype=float))]
        points += [(f"goal {i}", np.asarray(g, dtype=float)) for i, g in enumerate(goals)]
        for label, point in points:
            excess = float(max(np.max(low - point), np.max(point - high)))
            if excess > self.unseen_margin:
                return (f"outside training: the {label} at {np.round(point, 3).tolist()} lies {excess:.2f} m "
                        f"outside the training workspace of the {spec.name} policy, "
                        f"{np.round(low, 3).tolist()} .. {np.round(high, 3).tolist()} m (margin "
                        f"{self.unseen_margin} m); the policy was not trained there. A sampling planner "
                        "(rrt, birrt, ncrrt, ompl-rrtconnect) can plan this scene; "
                        "DRLPlanner(..., refuse_unseen=False) runs the policy anyway")
        return None

    def config(self) -> dict[str, Any]:
        meta = self.policy.meta
        return {"planner": self.name, "model": str(self.policy.path), "deterministic": self.deterministic,
                "resample_held": self._acting.draws_where_held, "refuse_unseen": self.refuse_unseen,
                "acting_layers": list(self.acting.layers),
                "timesteps": meta.get("timesteps"), "git_commit": meta.get("git_commit")}
