"""The layers that act between a policy and the arm; not in the paper.

``ActingEnv(env, ActingConfig())`` wraps the paper's ``ReachEnv`` and runs the layers as one
pipeline (``rayreach.acting.pipeline``) on one perception per step and one ray memory;
``ActingPolicy`` is the policy as the planner acts with it. Every layer is switched off by
name: ``ActingConfig().without("detour")``; ``ActingConfig.off()`` is the policy alone.
"""

from rayreach.acting.config import LAYERS, SOURCES, ActingConfig
from rayreach.acting.controller import ActingEnv
from rayreach.acting.resample import ActingPolicy

__all__ = ["LAYERS", "SOURCES", "ActingConfig", "ActingEnv", "ActingPolicy"]
