"""The policy network's shared part (paper: actor and critic share a feature extractor)."""

from __future__ import annotations

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor


class SharedMLP(BaseFeaturesExtractor):
    """An MLP over robot state and rays whose output feeds both the actor and the critic."""

    def __init__(self, observation_space: spaces.Box, layers: tuple[int, ...] = (256, 256)) -> None:
        super().__init__(observation_space, features_dim=layers[-1])
        sizes = [int(np.prod(observation_space.shape)), *layers]
        modules: list[torch.nn.Module] = []
        for a, b in zip(sizes[:-1], sizes[1:]):
            modules += [torch.nn.Linear(a, b), torch.nn.Tanh()]
        self.net = torch.nn.Sequential(*modules)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.net(obs)
