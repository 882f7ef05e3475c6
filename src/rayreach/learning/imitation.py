"""An imitation term beside PPO: before each rollout, a few steps of behaviour cloning on the
demonstrations a clone recorded in the run (``demos-KIND.npz``).

A clone alone is a starting point PPO may leave. The UR5's wait under a moving cover, cloned
into its actor, was gone after 5 M decisions of PPO (docs/log/2026-12-07-levers-measured.md,
"Demonstrations that wait for the cover"): going under the cover at once pays often enough.
Keeping the demonstrations in the objective, as DAPG does (Rajeswaran et al. 2018, "Learning complex
dexterous manipulation with deep RL and demonstrations"), holds the actor near the expert
in the expert's states while PPO shapes the rest. The steps come before a rollout, not
between rollout and update, so that the rollout's log-probabilities are those of the policy
that played it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

DEMOS_GLOB = "demos-*.npz"


def demos_name(kind: str) -> str:
    """The file in the run directory that holds the demonstrations of one clone."""
    return f"demos-{kind}.npz"


def save_demos(run: Path, kind: str, observations: list[np.ndarray], labels: list[np.ndarray]) -> Path:
    """Raw observations (normalised when used, with the statistics of then) and the expert's actions."""
    path = Path(run) / demos_name(kind)
    np.savez_compressed(path, observations=np.asarray(observations, dtype=np.float32),
                        labels=np.asarray(labels, dtype=np.float32))
    return path


def load_demos(run: Path) -> tuple[np.ndarray, np.ndarray]:
    """Every clone's demonstrations in ``run``, one array of observations and one of labels."""
    paths = sorted(Path(run).glob(DEMOS_GLOB))
    if not paths:
        raise FileNotFoundError(f"no demonstrations ({DEMOS_GLOB}) in {run}: an imitation term needs a clone "
                                "of the run first (rayreach clone, or --clone-at with --clone-kinds)")
    data = [np.load(p) for p in paths]
    return (np.concatenate([d["observations"] for d in data]), np.concatenate([d["labels"] for d in data]))


def imitation_callback(observations: np.ndarray, labels: np.ndarray, steps: int, batch_size: int = 256,
                       learning_rate: float = 3e-4, seed: int = 0):
    """An SB3 callback that takes ``steps`` Adam steps of the actor's mean action towards the
    labels (mean squared error, ``batch_size`` samples each) before each rollout. It waits
    while the actor is held (a critic warm-up), and logs ``train/imitation_loss``. Where the
    extractor is shared (the default), the steps move the critic's features too."""
    import torch
    from stable_baselines3.common.callbacks import BaseCallback

    if steps < 1 or len(observations) == 0 or len(observations) != len(labels):
        raise ValueError(f"an imitation term needs steps >= 1 and as many labels as observations; got {steps} "
                         f"steps, {len(observations)} observations, {len(labels)} labels")

    class ImitationCallback(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.rng: Any = None
            self.optimiser: Any = None

        def _on_training_start(self) -> None:
            self.optimiser = torch.optim.Adam(self.model.policy.parameters(), lr=learning_rate)
            self.rng = np.random.default_rng([seed, self.num_timesteps])  # a resumed part draws anew

        def _on_rollout_start(self) -> None:
            policy = self.model.policy
            if not any(p.requires_grad for p in policy.action_net.parameters()):
                return  # the actor is held: its values are not yet the critic's to judge
            normalize = self.model.get_vec_normalize_env()
            total = 0.0
            for _ in range(steps):
                pick = self.rng.integers(0, len(observations), size=min(batch_size, len(observations)))
                obs = observations[pick] if normalize is None else normalize.normalize_obs(observations[pick])
                x = torch.as_tensor(obs, dtype=torch.float32, device=policy.device)
                loss = torch.nn.functional.mse_loss(policy.get_distribution(x).distribution.mean,
                                                    torch.as_tensor(labels[pick], device=policy.device))
                self.optimiser.zero_grad()
                loss.backward()
                self.optimiser.step()
                total += loss.item()
            self.logger.record("train/imitation_loss", total / steps)

        def _on_step(self) -> bool:
            return True

    return ImitationCallback()
