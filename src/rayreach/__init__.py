"""rayreach: reactive motion planning for industrial arms with PPO and virtual laser rays.

Importing the package registers the Gymnasium environments listed in ``ENV_IDS``::

    import gymnasium as gym
    import rayreach

    env = gym.make("rayreach/Reach-UR5-v0", scenario="exp1")
    envs = gym.make_vec("rayreach/Reach-UR5-v0", num_envs=256, vectorization_mode="vector_entry_point")

``make_vec`` with ``vector_entry_point`` steps all worlds as one batch (``rayreach.env.vector``).

``rayreach.plan(scene, planner)`` plans and executes one query in simulation (``rayreach.api``).
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

__version__ = "0.1.0"

ENV_IDS: list[str] = []
for _robot in ("UR5", "KR16", "UR10"):
    _id = f"rayreach/Reach-{_robot}-v0"
    if _id not in registry:
        # no max_episode_steps: the env truncates itself at its step budget, with the paper's -5
        register(id=_id, entry_point="rayreach.env.reach:ReachEnv",
                 vector_entry_point="rayreach.env.vector:ReachVectorEnv", kwargs={"robot": _robot.lower()})
    ENV_IDS.append(_id)

from rayreach.api import STATUSES, PlanOutcome, plan  # noqa: E402  (numpy only; the simulator loads on a call)

__all__ = ["ENV_IDS", "STATUSES", "PlanOutcome", "__version__", "plan"]
