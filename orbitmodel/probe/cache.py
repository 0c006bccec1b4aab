"""Training windows held in memory, and the imagined latents of a frozen world model, computed once.

The world model is frozen and deterministic in eval mode, so the latents it imagines for a
window are the same in every epoch. On a GPU, upstream recomputes them every step (no cache,
``cache_windows = 0``). On a CPU, imagining dominates a probe step, so the ``cpu`` recipe
imagines a seeded subset of the training windows once (``RUN/probe/latents.safetensors``, reused
by --resume and by a new probe on the same world model, dataset and windows) and trains the
probe for many epochs on it: the same optimisation, far less compute.
"""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path

import torch
from safetensors import SafetensorError
from safetensors.torch import load_file, save_file
from torch.utils.data import Dataset, DistributedSampler

from orbitdata import schema as S
from orbitdata.load import collate_windows
from orbitdata.load.collate import WindowBatch
from orbitmodel.data import FRAME_STATES
from orbitmodel.train.progress import Progress

LATENT = "z_future"  # not a dataset column: the imagined latents of the horizon frames (N, n, D)
LAST = "z_last"  # not a dataset column: the latent of the last context frame (N, D)
CACHE_FILE = "latents.safetensors"
IMAGINE_BATCH = 64  # windows per world-model call


class TensorWindows(Dataset):
    """Windows as tensors (N, ...) keyed like the loader's items, with the loader's sampler API."""

    def __init__(self, tensors: dict[str, torch.Tensor]):
        sizes = {len(v) for v in tensors.values()}
        assert len(sizes) == 1, f"tensors of different lengths {sizes}"
        self.tensors = tensors

    def __len__(self) -> int:
        return len(next(iter(self.tensors.values())))

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        return {k: v[i] for k, v in self.tensors.items()}

    def __getitems__(self, indices) -> WindowBatch:
        idx = torch.as_tensor(list(indices), dtype=torch.long)
        return WindowBatch({k: v[idx] for k, v in self.tensors.items()})

    def sampler(
        self,
        shuffle: bool = True,
        seed: int = 0,
        drop_last: bool = False,
        rank: int | None = None,
        world_size: int | None = None,
    ) -> DistributedSampler:
        """Order a pure function of (seed, epoch), as ``WindowDataset.sampler``."""
        return DistributedSampler(
            self, num_replicas=world_size or 1, rank=rank or 0, shuffle=shuffle, seed=seed, drop_last=drop_last
        )


def subset(n: int, count: int, seed: int) -> list[int]:
    """``count`` of ``n`` window indices, a seeded draw, in table order (all when count >= n)."""
    if count >= n:
        return list(range(n))
    chosen = torch.randperm(n, generator=torch.Generator().manual_seed(seed))[:count]
    return sorted(chosen.tolist())


def gather(windows, indices: list[int], keys: tuple[str, ...]) -> dict[str, torch.Tensor]:
    """The ``keys`` of these windows, stacked (N, T, ...)."""
    parts = [collate_windows(windows.__getitems__(indices[i : i + 1024])) for i in range(0, len(indices), 1024)]
    return {k: torch.cat([p[k] for p in parts]) for k in keys}


@torch.no_grad()
def imagine(world_model, windows, indices: list[int], context: int, device: torch.device) -> dict[str, torch.Tensor]:
    """{z_future (N, n, D), z_last (N, D), states, actions} of these windows of T = context + n
    frames: the frozen world model encodes the context and imagines the rest from the actions."""
    out: dict[str, list[torch.Tensor]] = {LATENT: [], LAST: [], S.STATE: [], S.ACTION: []}
    progress = Progress("imagine", len(indices), 0)
    started = time.perf_counter()
    try:
        for i in range(0, len(indices), IMAGINE_BATCH):
            batch = collate_windows(windows.__getitems__(indices[i : i + IMAGINE_BATCH]))
            states, actions = batch[S.STATE], batch[S.ACTION]
            z = world_model.encode(batch[S.IMAGE][:, :context].to(device), states[:, :context].to(device))
            out[LATENT].append(world_model.rollout(z, actions[:, :-1].to(device)).float().cpu())  # (b, n, D)
            out[LAST].append(z[:, -1].float().cpu())  # (b, D)
            out[S.STATE].append(states)
            out[S.ACTION].append(actions)
            if FRAME_STATES in batch:  # a per-frame probe's targets
                out.setdefault(FRAME_STATES, []).append(batch[FRAME_STATES])
            done = min(i + IMAGINE_BATCH, len(indices))
            progress.update(done, {"windows_per_s": done / (time.perf_counter() - started)})
    finally:
        progress.close()
    return {k: torch.cat(v) for k, v in out.items()}


def cache_key(**facts) -> str:
    return hashlib.sha256(json.dumps(facts, sort_keys=True).encode()).hexdigest()[:16]


def load_cache(folder: Path, key: str) -> dict[str, torch.Tensor] | None:
    """The cached tensors when the file exists and was made for ``key``; else None."""
    path = folder / CACHE_FILE
    if not path.is_file():
        return None
    try:
        from safetensors import safe_open

        with safe_open(str(path), "pt") as f:
            if (f.metadata() or {}).get("key") != key:
                return None  # another world model or other windows
        return load_file(path)
    except (OSError, SafetensorError):
        return None  # a torn write: imagine again


def save_cache(folder: Path, key: str, tensors: dict[str, torch.Tensor]) -> None:
    tmp = folder / f".{CACHE_FILE}.tmp"
    save_file({k: v.contiguous() for k, v in tensors.items()}, tmp, metadata={"key": key})
    tmp.replace(folder / CACHE_FILE)
