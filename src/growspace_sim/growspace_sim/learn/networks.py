"""The CNN state encoder shared by every algorithm.

The paper's encoder: three convolutional layers, then a fully connected layer, ReLU
activations. For 84x84 observations the layers are the Nature-DQN ones (8x8/4, 4x4/2, 3x3/1),
as in Stable-Baselines3's ``NatureCNN``; the shape challenge's 28x28 image is too small for
them, so it gets 3x3 kernels (stride 2, 2, 1) instead.
"""

from __future__ import annotations

import gymnasium as gym
import torch
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

NATURE_MIN_SIDE = 36  # the smallest image the 8/4, 4/2, 3/1 stack accepts


class GrowSpaceCNN(BaseFeaturesExtractor):
    """Three conv layers and one fully connected layer over a channel-first uint8 image.

    Args:
        observation_space: Box of shape (C, H, W); Stable-Baselines3 transposes HWC images
            (``VecTransposeImage``) before they get here.
        features_dim: width of the fully connected output.
    """

    def __init__(self, observation_space: gym.spaces.Box, features_dim: int = 512) -> None:
        super().__init__(observation_space, features_dim)
        channels, height, width = observation_space.shape
        if min(height, width) >= NATURE_MIN_SIDE:
            layers = [(32, 8, 4), (64, 4, 2), (64, 3, 1)]
        else:
            layers = [(32, 3, 2), (64, 3, 2), (64, 3, 1)]
        modules: list[nn.Module] = []
        for out_channels, kernel, stride in layers:
            modules += [nn.Conv2d(channels, out_channels, kernel, stride), nn.ReLU()]
            channels = out_channels
        self.cnn = nn.Sequential(*modules, nn.Flatten())
        with torch.no_grad():
            flat = self.cnn(torch.zeros(1, *observation_space.shape)).shape[1]
        self.linear = nn.Sequential(nn.Linear(flat, features_dim), nn.ReLU())

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        # SB3's preprocess_obs already scaled the uint8 image to [0, 1].
        return self.linear(self.cnn(observations))
