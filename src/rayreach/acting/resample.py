"""Drawing anew where the arm is held: the policy as the planner acts with it. Not in the paper."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # acting reads a loaded policy; it does not load one
    from rayreach.acting.config import ActingConfig
    from rayreach.learning.policy import Policy


HELD_DRAW_STD = 0.5
"""The least standard deviation of a held arm's draw, per action dimension (actions lie in
[-1, 1]). Measured on 200 validation worlds with the stack, docs/acting.md ("resample")."""


class ActingPolicy:
    """The policy as the planner acts with it: its mean action, except where the last step
    held the arm (``info["acting"]["held"]``, ``rayreach.acting.ActingEnv``), where it draws
    one from its own distribution (``deterministic`` False: every action drawn, as SB3 draws
    them).

    A held arm (the arm's rule refused the step and every shorter share of it) sees what it
    saw; the mean action would repeat, and the arm stay held until the step budget ran out:
    17 of the KR16's 65 failures in 800 random worlds (docs/acting.md). A drawn action goes
    through the same layers as any other. ``reset(seed)`` starts each run, so a seeded run
    repeats.

    A policy trained to decide every ``decision_period`` control steps
    (``rayreach.env.decisions``) has its action held for that many calls of ``act``, as in
    training; a held arm draws at once.

    The draw's standard deviation is at least ``least_std`` in each dimension: a policy
    trained with little action noise (the UR5's default recipe starts at 0.3 and ends near
    0.17 in each translation) draws next to the refused mean and stays held until the step
    budget runs out. The shipped UR5 and KR16 policies carry more than 0.5 in every
    dimension and draw as before (docs/acting.md, "resample")."""

    def __init__(self, policy: Policy, deterministic: bool = True, resample: bool = True,
                 least_std: float = HELD_DRAW_STD) -> None:
        self.policy = policy
        self.deterministic = deterministic
        self.resample = resample
        self.least_std = least_std
        self._rng = np.random.default_rng(0)
        self.period = int(getattr(policy, "decision_period", 1))
        self._action: np.ndarray | None = None
        self._age = 0

    @classmethod
    def acting(cls, policy: Policy, config: ActingConfig, deterministic: bool = True) -> ActingPolicy:
        """``policy`` drawing where the arm was held as ``config`` says (``resample``,
        ``held_draw_std``)."""
        return cls(policy, deterministic=deterministic, resample=config.resample, least_std=config.held_draw_std)

    @property
    def draws_where_held(self) -> bool:
        """Whether a held arm's next action is drawn (the mean is acted on otherwise)."""
        return self.deterministic and self.resample

    def reset(self, seed: int) -> None:
        self._rng = np.random.default_rng(seed)
        self._action, self._age = None, 0

    def act(self, obs: np.ndarray, info: dict[str, Any] | None = None) -> np.ndarray:
        """The action for ``obs``; ``info``: the last step's (or reset's), which says whether the
        arm was held."""
        held = self.resample and info is not None and info.get("acting", {}).get("held", False)
        if self._action is not None and self._age < self.period and not (self.deterministic and held):
            self._age += 1
            return self._action
        if not self.deterministic:
            action = self.policy.act(obs, deterministic=False)
        elif held:
            action = self.policy.sample(obs, self._rng, self.least_std)
        else:
            action = self.policy.act(obs, deterministic=True)
        self._action, self._age = action, 1
        return action
