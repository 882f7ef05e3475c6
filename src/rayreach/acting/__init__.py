"""The layers that act between a policy and the arm; not in the paper.

``ActingEnv(env, ActingConfig())`` wraps the paper's ``ReachEnv`` and runs the layers as one
pipeline (``rayreach.acting.pipeline``) on one perception per step and one ray memory;
``ActingPolicy`` is the policy as the planner acts with it. Every layer is switched off by
name: ``ActingConfig().without("detour")``; ``ActingConfig.off()`` is the policy alone.
``ArmController`` runs the same pipeline for a real arm, from its joint angles and ray
readings, without the simulator.
"""

from typing import Any

from rayreach.acting.config import LAYERS, SOURCES, ActingConfig
from rayreach.acting.resample import ActingPolicy

__all__ = ["LAYERS", "SOURCES", "ActingConfig", "ActingEnv", "ActingPolicy", "ArmController"]


def __getattr__(name: str) -> Any:
    """``ActingEnv`` (it loads the simulator) and ``ArmController`` (numpy only), on first use."""
    if name == "ActingEnv":
        from rayreach.acting.controller import ActingEnv

        return ActingEnv
    if name == "ArmController":
        from rayreach.acting.arm_controller import ArmController

        return ArmController
    raise AttributeError(f"module 'rayreach.acting' has no attribute '{name}'")
