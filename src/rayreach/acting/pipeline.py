"""The acting layers as one pipeline of components round the paper's IK step.

Every layer does one or more of three things to a step, in this order: it may *propose* a
command in place of the policy's action (the first that proposes wins: final approach,
detour, stall nudge), *reshape* the command's pose step (the ray shield with its slide and
the workspace guard), or *veto* the IK solution before the arm takes it (the shield where IK
did not converge, the arm's rule, which asks for a shorter step). Each reads the step's one
``Perception`` and the episode's one ``RayMemory``; none looks at the obstacles.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import TYPE_CHECKING, Callable

import numpy as np

from rayreach.acting.memory import RayMemory
from rayreach.env.perception import Perception
from rayreach.sim.kinematics import IKResult

if TYPE_CHECKING:
    from rayreach.acting.shield import SafetyLayer


SHORTER = (0.5, 0.25, 0.125)
"""Shares of a step the arm's rule refused that are tried in turn, the longest first: a
shorter step may keep every blind link outside the rule's clearance (a deterministic policy
would repeat the refused step, held, until its step budget ran out: a KR16 tool stopped
0.5 mm short of the goal's tolerance)."""


class Verdict(Enum):
    ALLOW = "allow"
    REFUSE = "refuse"
    """The arm holds still this step."""
    SHORTER = "shorter"
    """Refused, but a shorter step (``rayreach.acting.controller.SHORTER``) may pass."""


@dataclass
class Command:
    """A motion on its way to the arm."""

    action: np.ndarray
    """In action units (6,), as proposed."""
    source: str
    """What chose it (``rayreach.acting.config.SOURCES``)."""
    straight: bool = False
    """The final approach's step, whose path was tested against every hit with the tool's
    shape: the shield keeps its rotation and lets it through where everything seen lies
    beyond ``travel``, IK may drop the orientation, and the arm's rule leaves the tool out."""
    travel: float | None = None
    """How far the motion goes in all, m, when known (the straight path to the goal)."""
    slide_to_goal: bool = True
    """The shield's slide may replace a held step by one towards the goal."""
    layer: SafetyLayer | None = None
    """The shield's settings for this step (None: the controller's); the detour's narrows it."""
    delta: np.ndarray = field(default_factory=lambda: np.zeros(6))
    """The pose step (dx, dy, dz in m, rotation vector in rad), once scaled."""


@dataclass
class Episode:
    """What the components share over an episode."""

    memory: RayMemory
    distances: list[float]
    """Distance to the current goal after each step since it became current, m, oldest first."""
    step_scale: np.ndarray
    """Metres and radians per unit of action (6,)."""
    refused: set[str] = field(default_factory=set)
    """The sources (``Command.source`` as proposed) whose step a veto held, every shorter
    share of it too, since the current goal became current."""


class Component:
    """One acting layer's part in the pipeline; a hook left as it is does nothing."""

    name: str = ""

    def reset(self, episode: Episode) -> None:
        """A new episode starts (the arm at its start, the memory holding the first scan)."""

    def propose(self, now: Perception, episode: Episode) -> Command | None:
        """A command in place of the policy's action, or None."""
        return None

    def reshape(self, command: Command, now: Perception, episode: Episode) -> float:
        """Change ``command.delta`` (and its source) in place; returns a reward term (the
        shielded term, 0 for the others)."""
        return 0.0

    def veto(self, command: Command, ik: IKResult, pose: np.ndarray, now: Perception, episode: Episode) -> Verdict:
        """Whether the arm may take ``ik``'s solution (tool ``pose``, 4 x 4) for ``command``."""
        return Verdict.ALLOW


@dataclass
class Chosen:
    """What the pipeline made of one action."""

    command: Command
    proposed: str
    """The source of the command before the shield reshaped it."""
    shaped: float
    """The shield's reward term."""
    ik: IKResult
    """The IK solution of the step tried last."""
    taken: bool
    """Whether the arm may take ``ik``'s solution (else it holds still)."""
    refused_by: str = ""
    """The component whose veto held the arm (its ``name``); "" where the step was taken."""


def choose(components: list[Component], episode: Episode, action: np.ndarray,
           solve: Callable[[np.ndarray, bool], IKResult], tool_pose: Callable[[IKResult], np.ndarray]) -> Chosen:
    """One step of the pipeline on ``action`` (6, action units): the first proposal wins over
    the action, every component reshapes the pose step, then IK (``solve(delta,
    keep_orientation)``) and the vetoes, with the shorter shares where a veto asks for them.
    Moves nothing: the caller takes ``ik`` or holds the arm (``ActingEnv`` in simulation,
    ``ArmController`` on a real arm)."""
    now = episode.memory.now
    command = Command(action, "policy")
    for component in components:
        proposed = component.propose(now, episode)
        if proposed is not None:
            command = proposed
            break
    command.delta = np.clip(command.action, -1.0, 1.0) * episode.step_scale
    source = command.source
    shaped = sum(component.reshape(command, now, episode) for component in components)

    def attempt(delta: np.ndarray) -> tuple[IKResult, Verdict, str]:
        ik = solve(delta, True)
        if not ik.converged and command.straight:
            # the final approach moves the tip and keeps the tool's orientation only where IK
            # can: a pose out of its reach stopped a KR16 tool 8 cm short of its goal for good
            ik = solve(delta, False)
        pose = tool_pose(ik)
        for component in components:
            verdict = component.veto(command, ik, pose, now, episode)
            if verdict is not Verdict.ALLOW:
                return ik, verdict, component.name
        return ik, Verdict.ALLOW, ""

    ik, verdict, refused_by = attempt(command.delta)
    for share in SHORTER if verdict is Verdict.SHORTER else ():
        ik, verdict, refused_by = attempt(command.delta * share)
        if verdict is Verdict.ALLOW:
            break
    if verdict is not Verdict.ALLOW:
        episode.refused.add(source)
    return Chosen(command, source, shaped, ik, verdict is Verdict.ALLOW, refused_by)


def held_by(chosen: Chosen) -> str:
    """What held the arm still on a step of ``chosen`` that did not move it: the component
    that refused it (``"shield"``, ``"arm_guard"``), the shield where it cut the step to
    nothing, else ``"still"`` (a step of nothing asked for, or IK left the joints as they were)."""
    if chosen.refused_by:
        return chosen.refused_by
    return "shield" if not np.any(chosen.command.delta) and np.any(chosen.command.action) else "still"
