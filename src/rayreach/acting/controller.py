"""``ActingEnv``: the paper's environment with the acting layers between the action and the arm.

A Gymnasium wrapper, so that evaluation, training with the layers in the loop and a user's
own loop all act the same way. Each step reports ``info["acting"]``: the ``source`` that
chose the executed motion (``rayreach.acting.config.SOURCES``) and whether the arm was
``held`` (its joints did not move: every try refused, or a step of nothing), and what
``proposed`` the command before the shield reshaped it (``policy``, ``final_approach``,
``detour`` or ``stall``).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.wrappers import OrderEnforcing, PassiveEnvChecker

from rayreach.acting.arm_guard import ArmCapsules
from rayreach.acting.config import ROBOT_RADII, ActingConfig, FinalApproachRadii
from rayreach.acting.layers import ArmRule, DetourStep, FinalApproachStep, Shield, StallNudge, applied_final_approach
from rayreach.acting.memory import RayMemory
from rayreach.acting.pipeline import Command, Component, Episode, Verdict
from rayreach.env.reach import ReachEnv
from rayreach.robots.urdf import TOOL_LINK

SHORTER = (0.5, 0.25, 0.125)
"""Shares of a step the arm's rule refused that are tried in turn, the longest first: a
shorter step may keep every blind link outside the rule's clearance (a deterministic policy
would repeat the refused step, held, until its step budget ran out: a KR16 tool stopped
0.5 mm short of the goal's tolerance)."""


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
        self.radii = ROBOT_RADII.get(spec.name, FinalApproachRadii())
        """The robot's final-approach radii (``ROBOT_RADII``)."""
        self.final_approach = None if config.final_approach is None else applied_final_approach(
            config.final_approach, spec.ee_step, spec.rot_step, spec.tool.length, spec.tool.radius,
            self.radii.radius, self.radii.axial_radius)
        """The final approach as applied: the robot's step, tool and radii filled in."""
        self.components = self._components(config)
        self._episode: Episode | None = None

    def _components(self, config: ActingConfig) -> list[Component]:
        """The pipeline in the order the layers act: proposers, then the shield, then the vetoes."""
        reach, spec, safety = self.reach, self.reach.spec_robot, config.safety
        components: list[Component] = []
        approach = self.final_approach
        if approach is not None:
            components.append(FinalApproachStep(approach))
        if config.detour is not None:
            arrive = self.radii.radius if approach is None else approach.radius
            guard = safety.workspace_guard + spec.ee_step  # the grid keeps a step inside the guard
            components.append(DetourStep(config.detour, safety, spec.tool.length, spec.tool.radius, arrive,
                                         reach.config.ray_range, guard))
        if approach is not None and approach.stall_steps > 0:
            components.append(StallNudge(approach))
        components.append(Shield(safety, reach.config.rewards))
        if safety.arm_clearance > 0:
            capsules = ArmCapsules(reach.scene, (*spec.blind_links, TOOL_LINK))
            components.append(ArmRule(capsules, safety))
        return components

    @property
    def memory(self) -> RayMemory:
        """The episode's ray memory (after ``reset``)."""
        if self._episode is None:
            raise RuntimeError("call reset() first")
        return self._episode.memory

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        memory = RayMemory()
        memory.add(self.reach.perceive(), moved=True)
        self._episode = Episode(memory, [info["distance"]], self.reach.step_scale)
        self._env_episode = self.reach.episodes
        self._goal_index = 0
        for component in self.components:
            component.reset(self._episode)
        return obs, info

    def step(self, action: np.ndarray):
        reach, episode = self.reach, self._episode
        a = reach.check_action(action)
        if episode is None or self._env_episode != reach.episodes:
            raise RuntimeError("call reset() before step()" + ("" if episode is None else
                               ": another wrapper has reset the environment since this one did"))
        now = episode.memory.now
        command = Command(a, "policy")
        for component in self.components:
            proposed = component.propose(now, episode)
            if proposed is not None:
                command = proposed
                break
        command.delta = np.clip(command.action, -1.0, 1.0) * episode.step_scale
        proposed = command.source
        shaped = sum(component.reshape(command, now, episode) for component in self.components)
        ik, verdict = self._attempt(command, command.delta, now)
        for share in SHORTER if verdict is Verdict.SHORTER else ():
            ik, verdict = self._attempt(command, command.delta * share, now)
            if verdict is Verdict.ALLOW:
                break
        taken = verdict is Verdict.ALLOW
        q_before = now.q
        obs, reward, terminated, truncated, info = reach.advance(ik, taken)
        episode.memory.add(reach.perceive(), moved=taken)
        if info["goal_index"] != self._goal_index:
            self._goal_index, episode.distances = info["goal_index"], []
        episode.distances.append(info["distance"])
        info["reward_terms"]["shielded"] = shaped
        held = not taken or np.array_equal(q_before, reach.q)
        info["acting"] = {"source": "held" if held else command.source, "proposed": proposed, "held": held}
        return obs, reward + shaped, terminated, truncated, info

    def _attempt(self, command: Command, delta: np.ndarray, now) -> tuple:
        """IK for ``delta`` and the vetoes' verdict on it, the first refusal winning."""
        reach, episode = self.reach, self._episode
        ik = reach.solve(delta)
        if not ik.converged and command.straight:
            # the final approach moves the tip and keeps the tool's orientation only where IK
            # can: a pose out of its reach stopped a KR16 tool 8 cm short of its goal for good
            ik = reach.solve(delta, keep_orientation=False)
        pose = reach.tool_pose(ik)
        for component in self.components:
            verdict = component.veto(command, ik, pose, now, episode)  # type: ignore[arg-type]
            if verdict is not Verdict.ALLOW:
                return ik, verdict
        return ik, Verdict.ALLOW
