"""The paper's MDP: ``ReachEnv`` (obs 142, a pose step solved by DLS IK, the paper's reward).

Nothing here imports ``rayreach.acting``: the layers that act between a policy and the arm
wrap this environment from outside (``rayreach.acting.ActingEnv``)."""

from rayreach.env.reach import OBS_SIZE, OUTCOMES, EnvConfig, ReachEnv, episode_outcome

__all__ = ["OBS_SIZE", "OUTCOMES", "EnvConfig", "ReachEnv", "episode_outcome"]
