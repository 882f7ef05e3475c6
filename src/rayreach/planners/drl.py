"""The paper's planner: a trained PPO policy acting on rays and robot state, step by step."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from rayreach.acting.config import ActingConfig
from rayreach.acting.resample import ActingPolicy
from rayreach.learning.policy import load_policy
from rayreach.planners.base import ReactivePlanner

MODELS_DIR = Path(__file__).resolve().parents[3] / "models"
"""The repository's shipped policies (``models/ur5.zip``, ``models/kr16.zip``)."""


def shipped_model(robot: str) -> Path:
    """The shipped policy for ``robot``: ``models/<robot>.zip`` in the working directory or
    in the repository; the error names both places."""
    for folder in (Path("models"), MODELS_DIR):
        candidate = folder / f"{robot}.zip"
        if candidate.is_file():
            return candidate
    raise FileNotFoundError(
        f"no shipped policy for '{robot}': looked for models/{robot}.zip and {MODELS_DIR / (robot + '.zip')}; "
        "pass a model with --model (a checkpoint.zip or an exported bundle)"
    )


class DRLPlanner(ReactivePlanner):
    """The trained policy acting through ``acting`` (``ActingConfig.off()``, planner
    ``drl-alone``: the policy itself, as the paper's agent acted)."""

    def __init__(self, model: str | Path, deterministic: bool = True, acting: ActingConfig = ActingConfig(),
                 name: str = "drl") -> None:
        self.policy = load_policy(model)
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
