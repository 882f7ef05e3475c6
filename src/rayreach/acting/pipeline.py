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
from typing import TYPE_CHECKING

import numpy as np

from rayreach.acting.memory import RayMemory
from rayreach.env.perception import Perception
from rayreach.sim.kinematics import IKResult

if TYPE_CHECKING:
    from rayreach.acting.shield import SafetyLayer


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
