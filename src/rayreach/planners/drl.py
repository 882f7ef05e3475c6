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


class DRLPlanner(ReactivePlanner):
    """The trained policy acting through ``acting`` (``ActingConfig.off()``, planner
    ``drl-alone``: the policy itself, as the paper's agent acted)."""

    def __init__(self, model: str | Path, deterministic: bool = True, acting: ActingConfig = ActingConfig(),
                 name: str = "drl") -> None:
        self.policy = load_policy(resolve_model(model))
        self.deterministic = deterministic
        self.acting = acting
        self.name = name
        self.observation = self.policy.observation
        self._acting = ActingPolicy(self.policy, deterministic=deterministic, resample=acting.resample)

    @property
    def robot(self) -> str:
        return self.policy.robot

    def reset(self, seed: int) -> None:
        self._acting.reset(seed)

    def act(self, observation: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        return self._acting.act(observation, info)

    def config(self) -> dict[str, Any]:
        meta = self.policy.meta
        return {"planner": self.name, "model": str(self.policy.path), "deterministic": self.deterministic,
                "resample_held": self._acting.draws_where_held, "acting_layers": list(self.acting.layers),
                "timesteps": meta.get("timesteps"), "git_commit": meta.get("git_commit")}
