"""The paper's MDP: ``ReachEnv`` (obs 142, a pose step solved by DLS IK, the paper's reward).

Nothing here imports ``rayreach.acting``: the layers that act between a policy and the arm
wrap this environment from outside (``rayreach.acting.ActingEnv``)."""

from typing import Any

__all__ = ["OBS_SIZE", "OUTCOMES", "EnvConfig", "ReachEnv", "episode_outcome"]


def __getattr__(name: str) -> Any:
    """``rayreach.env.ReachEnv`` and its neighbours, imported on first use: the simulator loads
    with them, and the observation and perception modules serve a real arm without it."""
    if name in __all__:
        from rayreach.env import reach

        return getattr(reach, name)
    raise AttributeError(f"module 'rayreach.env' has no attribute '{name}'")
