"""A loaded policy: the actor with its frozen observation normalisation, for acting."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rayreach.env.observation import ObservationConfig
from rayreach.learning.bundles import CheckpointError, Normalization, read_bundle_meta
from rayreach.scenarios import RANDOM


@dataclass
class Policy:
    """A loaded policy: ``act(obs)`` normalises with the frozen statistics and runs the actor."""

    model: Any
    normalization: Normalization | None
    meta: dict[str, Any]
    path: Path

    @property
    def robot(self) -> str:
        return str(self.meta["robot"])

    @property
    def observation(self) -> ObservationConfig:
        """What the policy was trained to see (the paper's 142 values where its run predates
        the choice)."""
        saved = self.meta.get("config", {}).get("observation")
        return ObservationConfig(**saved) if saved else ObservationConfig()

    @property
    def suite(self) -> str:
        """The drawn worlds it was trained in (``TrainConfig.suite``; "random" before the choice)."""
        return str(self.meta.get("config", {}).get("suite", RANDOM))

    @property
    def decision_period(self) -> int:
        """Control steps each of its actions is held for (``TrainConfig.decision_period``; 1
        where its run predates the choice)."""
        return int(self.meta.get("config", {}).get("decision_period", 1))

    def act(self, obs: np.ndarray, deterministic: bool = True) -> np.ndarray:
        action, _ = self.model.predict(self._normalized(obs), deterministic=deterministic)
        return action

    def sample(self, obs: np.ndarray, rng: np.random.Generator, least_std: float = 0.0) -> np.ndarray:
        """An action drawn from the policy's Gaussian with ``rng`` (not torch's global
        generator, so that a seeded run repeats), clipped to the action space as
        ``act`` clips; each dimension's standard deviation at least ``least_std``."""
        import torch

        with torch.no_grad():
            tensor, _ = self.model.policy.obs_to_tensor(self._normalized(obs))
            gaussian = self.model.policy.get_distribution(tensor).distribution
            mean, std = gaussian.mean.numpy()[0], gaussian.stddev.numpy()[0]
        space = self.model.action_space
        std = np.maximum(std, least_std)
        return np.clip(mean + std * rng.standard_normal(mean.shape), space.low, space.high).astype(np.float32)

    def _normalized(self, obs: np.ndarray) -> np.ndarray:
        return self.normalization(obs) if self.normalization is not None else obs


def load_policy(path: str | Path, device: str = "cpu") -> Policy:
    """Load a model or checkpoint bundle for acting (normalisation frozen).

    Sets torch to one thread: acting runs one observation per call, where intra-op threads
    only add overhead and spin against an evaluation's other workers or a training run
    (exp3 DRL runs took 1.4 to 9.8 s with two threads per worker, 0.25 s with one)."""
    import torch
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    meta, norm = read_bundle_meta(path)
    try:
        model = PPO.load(str(path), device=device)
    except Exception as exc:  # SB3 raises many kinds on a damaged zip
        raise CheckpointError(f"{path}: the PPO model inside cannot be loaded: {exc}") from exc
    obs_size = model.observation_space.shape
    if tuple(obs_size) != tuple(meta.get("obs_shape", obs_size)):
        raise CheckpointError(f"{path}: observation shape {obs_size} does not match its metadata")
    return Policy(model, Normalization.from_arrays(norm), meta, Path(path))
