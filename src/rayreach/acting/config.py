"""Which acting layers act, with what settings: one switch per layer, by name."""

from __future__ import annotations

from dataclasses import dataclass, replace

from rayreach.acting.detour import Detour
from rayreach.acting.final_approach import FinalApproach
from rayreach.acting.resample import HELD_DRAW_STD
from rayreach.acting.shield import ACTING_SAFETY, SafetyLayer

LAYERS = ("final_approach", "ray_shield", "slide", "workspace_guard", "arm_guard", "detour", "resample")
"""Every acting layer, by the name that switches it off (``ActingConfig.without``, ``--no-LAYER``)."""

SOURCES = ("policy", "final_approach", "stall", "detour", "slide", "held")
"""What can choose a step's executed motion (``info["acting"]["source"]``); ``held``: the arm
held still, whatever was asked of it."""


@dataclass(frozen=True)
class FinalApproachRadii:
    """Per robot: how near the goal the final approach takes over, m. Tuned on random worlds,
    so acting settings, not robot facts."""

    radius: float = 0.1
    axial_radius: float | None = None


ROBOT_RADII = {
    # the enlarged goal the curriculum trains at; along the axis 0.13 and 0.15 m alike, 0.2 m worse
    "ur5": FinalApproachRadii(0.1, 0.13),
    "kr16": FinalApproachRadii(0.2, None),  # chosen from 0.1..0.3 m
}
"""The final approach's radii per robot (``FinalApproach.radius``, ``axial_radius``);
robots not named here take ``FinalApproachRadii()``."""


@dataclass(frozen=True)
class ActingConfig:
    """The acting layers of a controller; the defaults are the shipped planner's stack."""

    final_approach: FinalApproach | None = FinalApproach()
    """The straight step at a goal the policy has nearly reached (None: off)."""
    safety: SafetyLayer = ACTING_SAFETY
    """Ray shield with its hit memory, slide, workspace guard and the arm's rule."""
    detour: Detour | None = Detour()
    """The way round what the rays saw for a stalled policy (None: off)."""
    resample: bool = True
    """Draw the action from the policy's distribution where the arm was held."""
    held_draw_std: float = HELD_DRAW_STD
    """The least standard deviation of that draw, per action dimension (``ActingPolicy``)."""

    @classmethod
    def off(cls) -> "ActingConfig":
        """Every layer off: the policy alone, as the paper's agent acted."""
        return cls().without(*LAYERS)

    @classmethod
    def training(cls) -> "ActingConfig":
        """The layers training keeps in the loop: those that reshape or refuse the policy's own
        step (shield, workspace guard, arm's rule). The final approach, the detour and the
        slide replace its action outright, and PPO would store an action that had no effect
        on what followed (docs/acting.md, "Training with the layers")."""
        return cls().without("final_approach", "detour", "slide", "resample")

    def without(self, *names: str) -> "ActingConfig":
        """This configuration with the named layers (``LAYERS``) off."""
        unknown = sorted(set(names) - set(LAYERS))
        if unknown:
            raise ValueError(f"unknown acting layer(s) {unknown}; known: {', '.join(LAYERS)}")
        safety, config = self.safety, self
        if "ray_shield" in names:
            safety = replace(safety, ray_shield=0.0, memory_steps=0)
        if "slide" in names:
            safety = replace(safety, slide=0.0)
        if "workspace_guard" in names:
            safety = replace(safety, workspace_guard=0.0)
        if "arm_guard" in names:
            safety = replace(safety, arm_clearance=0.0, guard_tool=False, tool_clearance=None, arm_rays=False)
        if "final_approach" in names:
            config = replace(config, final_approach=None)
        if "detour" in names:
            config = replace(config, detour=None)
        if "resample" in names:
            config = replace(config, resample=False)
        return replace(config, safety=safety)

    @property
    def layers(self) -> tuple[str, ...]:
        """The names of the layers that are on, in ``LAYERS`` order."""
        s = self.safety
        on = {"final_approach": self.final_approach is not None, "ray_shield": s.ray_shield > 0,
              "slide": s.slide > 0 and s.active, "workspace_guard": s.workspace_guard > 0,
              "arm_guard": s.arm_clearance > 0, "detour": self.detour is not None, "resample": self.resample}
        return tuple(name for name in LAYERS if on[name])
