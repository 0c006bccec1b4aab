"""Raw dataset states in, z-scored states inside: the one place every model keeps the train
split's state statistics (``meta/stats.json``) as buffers, so its weights file carries them and
callers pass raw dataset values."""

from __future__ import annotations

import torch

MIN_STD = 1e-3  # a state entry that never moves (e.g. p at frame 0) is not blown up


class NormalisedStates:
    """Mixin for an ``nn.Module``: buffers ``state_mean`` and ``state_std`` (16,), set from a
    dataset with :meth:`set_state_stats`, applied by :meth:`normalise_states`."""

    def register_state_stats(self, dim: int) -> None:
        self.register_buffer("state_mean", torch.zeros(dim))
        self.register_buffer("state_std", torch.ones(dim))

    def set_state_stats(self, mean, std) -> None:
        """The dataset's state mean and std (16,) from meta/stats.json."""
        self.state_mean.copy_(torch.as_tensor(mean, dtype=torch.float32))
        self.state_std.copy_(torch.as_tensor(std, dtype=torch.float32).clamp(min=MIN_STD))

    def normalise_states(self, states: torch.Tensor) -> torch.Tensor:
        """(..., 16) raw -> (..., 16) z-scored."""
        return (states - self.state_mean) / self.state_std
