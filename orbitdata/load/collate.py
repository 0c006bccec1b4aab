"""Batches: windows decoded straight into one batch, and the collate function that keeps it.

``WindowDataset.__getitems__`` (which ``DataLoader`` calls for a whole batch) decodes every
window of the batch into one preallocated tensor per key and returns them as a
:class:`WindowBatch`. With ``collate_fn=collate_windows`` that batch is returned as is: no
``torch.stack`` copy of every image. Any other collate function sees a plain list of per-window
dicts (views into the batch), so ``default_collate`` still works, one copy slower.
"""

from __future__ import annotations

import torch
from torch.utils.data import default_collate


class WindowBatch(list):
    """A list of per-window dicts that also holds them stacked, in ``.stacked``."""

    def __init__(self, stacked: dict[str, torch.Tensor]):
        n = len(next(iter(stacked.values())))
        super().__init__({k: v[j] for k, v in stacked.items()} for j in range(n))
        self.stacked = stacked  # key -> (B, T, ...)


def collate_windows(items):
    """``collate_fn`` for window datasets: the ready batch when there is one, else ``default_collate``."""
    if isinstance(items, WindowBatch):
        return items.stacked
    return default_collate(items)
