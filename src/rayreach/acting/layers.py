"""Each acting layer as a pipeline component (``rayreach.acting.pipeline``); the maths of each
lives in its own module (final_approach, detour, shield, arm_guard)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from rayreach.acting.arm_guard import ArmGuard, LinkCapsules
from rayreach.acting.config import ROBOT_RADII, ActingConfig, FinalApproachRadii
from rayreach.acting.detour import Detour, DetourState
from rayreach.acting.final_approach import FinalApproach
from rayreach.acting.pipeline import Command, Component, Episode, Verdict
from rayreach.acting.shield import SafetyLayer, remembered_rays
from rayreach.env import rewards as R
from rayreach.env.perception import Perception
from rayreach.robots.spec import RobotSpec
from rayreach.sim.kinematics import IKResult


class FinalApproachStep(Component):
    """Proposes the straight step at a goal within reach (``FinalApproach``)."""

    name = "final_approach"

    def __init__(self, approach: FinalApproach) -> None:
        self.approach = approach

    def propose(self, now: Perception, episode: Episode) -> Command | None:
        if self.approach.give_way and self.name in episode.refused:
            return None
        offset = now.goal_offset
        action = self.approach.action(offset, now.hits, now.tool_direction)
        if action is None:
            return None
        return Command(action, self.name, straight=True, travel=float(np.linalg.norm(offset)), slide_to_goal=False)


class StallNudge(Component):
    """Proposes a step at the goal once the policy has stalled (``FinalApproach.stall_steps``;
    off by default)."""

    name = "stall"

    def __init__(self, approach: FinalApproach) -> None:
        self.approach = approach

    def propose(self, now: Perception, episode: Episode) -> Command | None:
        if not self.approach.stalled(episode.distances):
            return None
        return Command(FinalApproach.towards(now.goal_offset), self.name)


class DetourStep(Component):
    """Proposes the next step round what the rays have seen once the policy has stalled
    (``Detour``); on its steps the shield narrows to the detour's clearance."""

    name = "detour"

    def __init__(self, detour: Detour, safety: SafetyLayer, tool_length: float, tool_radius: float,
                 arrive: float, ray_range: float, guard: float) -> None:
        self.detour, self.layer = detour, detour.shield(safety)
        self._tool, self._arrive, self._range, self._guard = (tool_length, tool_radius), arrive, ray_range, guard
        self.state: DetourState | None = None

    def reset(self, episode: Episode) -> None:
        now = episode.memory.now
        self.state = DetourState(self.detour, episode.memory, *self._tool, self._arrive, self._range,
                                 now.workspace_low + self._guard, now.workspace_high - self._guard)

    def propose(self, now: Perception, episode: Episode) -> Command | None:
        assert self.state is not None, "reset() first"
        action = self.state.action(now.step, now.ee_position, now.goal, now.tool_direction, episode.distances)
        return None if action is None else Command(action, self.name, slide_to_goal=False, layer=self.layer)


class Shield(Component):
    """Reshapes the step with the ray shield (and its hit memory), the workspace guard and the
    slide (``SafetyLayer``); vetoes an unconverged IK solution that went where the shield
    did not let the step go."""

    name = "shield"

    def __init__(self, layer: SafetyLayer, rewards: R.RewardWeights) -> None:
        self.layer, self.rewards = layer, rewards
        self._rules: tuple | None = None
        self._step_layer = layer

    def reshape(self, command: Command, now: Perception, episode: Episode) -> float:
        layer = command.layer or self.layer
        self._step_layer, self._rules = layer, None
        if not layer.active:
            return 0.0
        own = self.layer
        distances, directions = remembered_rays(now, episode.memory.before(own.memory_steps), own.ray_shield)
        self._rules = (now.ee_position, now.workspace_low, now.workspace_high, distances, directions,
                       command.travel)
        towards_goal = (FinalApproach.towards(now.goal_offset)[:3] * episode.step_scale[:3]
                        if command.slide_to_goal else None)
        commanded = command.delta[:3]
        command.delta, slid = layer.shape(command.delta, *self._rules, towards_goal, keep_rotation=command.straight)
        shielded = R.shielded_reward(commanded, command.delta[:3], self.rewards) if command.source == "policy" else 0.0
        if slid:
            command.source = "slide"
        return shielded

    def veto(self, command: Command, ik: IKResult, pose: np.ndarray, now: Perception, episode: Episode) -> Verdict:
        if self._rules is None or ik.converged or self._step_layer.allows(pose[:3, 3] - now.ee_position, *self._rules):
            return Verdict.ALLOW
        return Verdict.REFUSE


class ArmRule(Component):
    """Vetoes a joint step that brings a blind link (and the tool, except on the final
    approach's steps) nearer than its clearance to what the rays saw (``ArmGuard``)."""

    name = "arm_guard"

    def __init__(self, capsules: LinkCapsules, layer: SafetyLayer) -> None:
        self.capsules, self.layer = capsules, layer
        self.guard = ArmGuard(capsules, layer.arm_clearance, layer.guard_tool, layer.tool_clearance)

    def veto(self, command: Command, ik: IKResult, pose: np.ndarray, now: Perception, episode: Episode) -> Verdict:
        points = episode.memory.seen_points(self.layer.arm_memory_steps)
        return Verdict.ALLOW if self.guard.allows(now.q, ik.q, points, tool=not command.straight) else Verdict.SHORTER


def applied_final_approach(approach: FinalApproach, ee_step: float, rot_step: float, tool_length: float,
                           tool_radius: float, radius: float, axial_radius: float | None) -> FinalApproach:
    """``approach`` with the robot's step and tool, and the given radii where it leaves them None."""
    return replace(approach, ee_step=ee_step, rot_step=rot_step, tool_length=tool_length, tool_radius=tool_radius,
                   radius=radius if approach.radius is None else approach.radius,
                   axial_radius=axial_radius if approach.axial_radius is None else approach.axial_radius)


def acting_components(config: ActingConfig, spec: RobotSpec, ray_range: float, rewards: R.RewardWeights,
                      capsules: LinkCapsules | None) -> tuple[list[Component], FinalApproach | None, FinalApproachRadii]:
    """The pipeline of ``config`` for a robot, in the order the layers act: proposers, then the
    shield, then the vetoes; with the final approach as applied (the robot's step, tool and
    radii filled in, ``ROBOT_RADII``) and those radii. ``capsules``: the links the arm's rule
    keeps clear (its blind links and the tool), needed where ``safety.arm_clearance`` > 0."""
    safety = config.safety
    radii = ROBOT_RADII.get(spec.name, FinalApproachRadii())
    approach = None if config.final_approach is None else applied_final_approach(
        config.final_approach, spec.ee_step, spec.rot_step, spec.tool.length, spec.tool.radius, radii.radius,
        radii.axial_radius)
    components: list[Component] = []
    if approach is not None:
        components.append(FinalApproachStep(approach))
    if config.detour is not None:
        arrive = radii.radius if approach is None else approach.radius
        guard = safety.workspace_guard + spec.ee_step  # the grid keeps a step inside the guard
        components.append(DetourStep(config.detour, safety, spec.tool.length, spec.tool.radius, arrive, ray_range,
                                     guard))
    if approach is not None and approach.stall_steps > 0:
        components.append(StallNudge(approach))
    components.append(Shield(safety, rewards))
    if safety.arm_clearance > 0:
        if capsules is None:
            raise ValueError("the arm's rule (safety.arm_clearance > 0) needs the links' capsules; "
                             "or switch it off: ActingConfig().without('arm_guard')")
        components.append(ArmRule(capsules, safety))
    return components, approach, radii
