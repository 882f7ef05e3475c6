"""``ActingEnv``: the paper's environment with the acting layers between the action and the arm.

A Gymnasium wrapper, so that evaluation, training with the layers in the loop and a user's
own loop all act the same way. Each step reports ``info["acting"]``: the ``source`` that
chose the executed motion (``rayreach.acting.config.SOURCES``) and whether the arm was
``held`` (its joints did not move: every try refused, or a step of nothing), and what
``proposed`` the command before the shield reshaped it (``policy``, ``final_approach``,
``detour`` or ``stall``), and on a held step what ``held_by`` it (``held_by``).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.wrappers import OrderEnforcing, PassiveEnvChecker

from rayreach.acting.arm_guard import guarded_links
from rayreach.acting.config import ActingConfig
from rayreach.acting.layers import acting_components
from rayreach.acting.memory import RayMemory
from rayreach.acting.mesh_capsules import ArmCapsules
from rayreach.acting.pipeline import SHORTER, Episode, choose, held_by
from rayreach.env.perception import Perception, seen_points
from rayreach.env.reach import ReachEnv
from rayreach.sim.sensors import RayModel, arm_layout

__all__ = ["PASSED_WRAPPERS", "SHORTER", "ActingEnv"]

PASSED_WRAPPERS = (OrderEnforcing, PassiveEnvChecker)
"""Wrappers ``gym.make`` adds that only check calls: an ``ActingEnv`` may sit outside them."""


class ActingEnv(gym.Wrapper):
    """``env`` (a ``ReachEnv``) acting through the layers of ``config``."""

    def __init__(self, env: ReachEnv | gym.Env, config: ActingConfig = ActingConfig()) -> None:
        super().__init__(env)
        reach: ReachEnv = env.unwrapped  # type: ignore[assignment]
        if not isinstance(reach, ReachEnv):
            raise TypeError(f"ActingEnv wraps a rayreach ReachEnv, got {type(reach).__name__}")
        inner = env
        while isinstance(inner, gym.Wrapper):  # steps go to the ReachEnv itself, past these
            if not isinstance(inner, PASSED_WRAPPERS):
                raise TypeError(f"ActingEnv steps the ReachEnv itself and would pass {type(inner).__name__} by; "
                                f"wrap the ActingEnv in it instead (allowed inside: "
                                f"{', '.join(w.__name__ for w in PASSED_WRAPPERS)})")
            inner = inner.env
        self.reach = reach
        self.config = config
        spec = reach.spec_robot
        guard = config.safety.arm_clearance > 0
        self._arm_rays = (RayModel(spec, reach.config.ray_range, arm_layout(spec))
                          if config.safety.reads_arm_rays else None)
        """The rays round the upper arm and the forearm that the arm's rule reads (``SafetyLayer.arm_rays``)."""
        capsules = ArmCapsules(reach.scene, guarded_links(spec, self._arm_rays is not None)) if guard else None
        self.components, self.final_approach, self.radii = acting_components(
            config, spec, reach.config.ray_range, reach.config.rewards, capsules)
        """The pipeline; the final approach as applied (the robot's step, tool and radii filled
        in); the robot's final-approach radii (``ROBOT_RADII``)."""
        self._episode: Episode | None = None

    @property
    def memory(self) -> RayMemory:
        """The episode's ray memory (after ``reset``)."""
        if self._episode is None:
            raise RuntimeError("call reset() first")
        return self._episode.memory

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        memory = RayMemory()
        memory.add(self._perceive(), moved=True)
        self._episode = Episode(memory, [info["distance"]], self.reach.step_scale)
        self._env_episode = self.reach.episodes
        self._goal_index = 0
        for component in self.components:
            component.reset(self._episode)
        return obs, info

    def _perceive(self) -> Perception:
        """The env's perception, with what the arm's rays see where the arm's rule reads them."""
        now = self.reach.perceive()
        if self._arm_rays is None:
            return now
        reach, ray_range = self.reach, self.reach.config.ray_range
        origins, directions = self._arm_rays.world_rays(reach.frames)
        fractions = reach.caster.cast(origins, directions, ray_range)
        return replace(now, arm_points=seen_points(origins, directions, fractions, ray_range))

    def step(self, action: np.ndarray):
        reach, episode = self.reach, self._episode
        a = reach.check_action(action)
        if episode is None or self._env_episode != reach.episodes:
            raise RuntimeError("call reset() before step()" + ("" if episode is None else
                               ": another wrapper has reset the environment since this one did"))
        chosen = choose(self.components, episode, a, reach.solve, reach.tool_pose)
        taken = chosen.taken
        q_before = reach.q
        obs, reward, terminated, truncated, info = reach.advance(chosen.ik, taken)
        episode.memory.add(self._perceive(), moved=taken)
        if info["goal_index"] != self._goal_index:
            self._goal_index, episode.distances, episode.refused = info["goal_index"], [], set()
        episode.distances.append(info["distance"])
        info["reward_terms"]["shielded"] = chosen.shaped
        held = not taken or np.array_equal(q_before, reach.q)
        info["acting"] = {"source": "held" if held else chosen.command.source, "proposed": chosen.proposed,
                          "held": held, "held_by": held_by(chosen) if held else ""}
        return obs, reward + chosen.shaped, terminated, truncated, info
