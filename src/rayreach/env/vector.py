"""The batched environment through Gymnasium's vector API.

``gymnasium.make_vec("rayreach/Reach-UR5-v0", num_envs=256, vectorization_mode="vector_entry_point")``
gives a ``ReachVectorEnv``: ``BatchedReachEnv``'s worlds with Gymnasium's signatures
(``terminated`` and ``truncated`` apart, infos as a dict of arrays). A world whose episode
ends is reset in the same step (``AutoresetMode.SAME_STEP``): its last observation and info
are in ``infos["final_obs"]`` and ``infos["final_info"]`` (masks ``"_final_obs"`` and
``"_final_info"``). Those are all ``infos`` holds: a world whose episode goes on reports no
info, and ``reset`` returns ``{}`` (``BatchedReachEnv``'s infos).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from rayreach.env.batched import BatchedReachEnv
from rayreach.scenarios import RANDOM, Scenario


class ReachVectorEnv(VectorEnv):
    """``num_envs`` reach tasks of one robot (see the module docstring)."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(self, robot: str | None = None, num_envs: int = 256,
                 scenario: str | Path | Scenario = RANDOM, **kwargs: Any) -> None:
        self.batched = BatchedReachEnv(robot, num_envs, scenario, **kwargs)
        self.num_envs = num_envs
        self.single_observation_space = self.batched.observation_space
        self.single_action_space = self.batched.action_space
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.render_mode = None

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None):
        """``seed``: one int (world ``i`` gets ``seed + i``) or one per world."""
        if isinstance(seed, (list, tuple)):
            if len(seed) != self.num_envs:
                raise ValueError(f"reset needs one seed per world ({self.num_envs}), got {len(seed)}")
            self.batched._seeds = list(seed)
        elif seed is not None:
            self.batched.seed(int(seed))
        return self.batched.reset(), {}

    def step(self, actions: np.ndarray):
        obs, rewards, dones, infos = self.batched.step(actions)
        truncated = np.array([bool(info.get("TimeLimit.truncated")) for info in infos]) & dones
        merged: dict[str, Any] = {}
        for i in np.flatnonzero(dones):
            final = dict(infos[i])
            final_obs = final.pop("terminal_observation")
            final.pop("TimeLimit.truncated")  # SB3's key; Gymnasium has ``truncated`` for it
            merged = self._add_info(merged, {"final_obs": final_obs, "final_info": final}, int(i))
        return obs, rewards, dones & ~truncated, truncated, merged

    def close_extras(self, **kwargs: Any) -> None:
        self.batched.close()
