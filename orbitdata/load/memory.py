"""Output buffers for decoded batches: shared memory in DataLoader workers, recycled otherwise.

A batch of 64 windows of 20 frames at 224 px is 190 MB. Fresh memory costs page faults and
zeroing of the order of decoding the JPEGs, several times what writing the same memory again
costs. So in the process that trains, a large
buffer goes back to a small pool once nothing references it any more (the batch and every
view of it are gone) and a later batch of the same shape reuses it.

In a worker the buffer is allocated in shared memory instead, as ``default_collate`` does,
so sending it to the main process costs no copy; the worker cannot know when the main
process is done with it, so it is never recycled.
"""

from __future__ import annotations

import math
import threading
import weakref

import torch

MIN_POOLED_BYTES = 16 << 20  # below this, malloc reuses freed memory anyway


class _Pool:
    """Large buffers of this process that no tensor uses any more, by (shape, dtype)."""

    def __init__(self, keep: int = 2):
        self.keep = keep  # free buffers kept per shape; more go back to the OS
        self.free: dict[tuple, list[torch.Tensor]] = {}
        self.lock = threading.Lock()  # finalizers may run in a pin-memory thread

    def take(self, shape: tuple[int, ...], dtype: torch.dtype) -> torch.Tensor:
        key = (shape, dtype)
        with self.lock:
            free = self.free.get(key)
            base = free.pop() if free else None
        if base is None:
            base = torch.empty(shape, dtype=dtype)
        # The caller's tensor holds this numpy view; when the last tensor on its memory is
        # gone, so is the view, and the finalizer hands ``base`` back.
        handle = base.numpy().view()
        weakref.finalize(handle, self.give, key, base).atexit = False
        return torch.from_numpy(handle)

    def give(self, key: tuple, base: torch.Tensor) -> None:
        with self.lock:
            free = self.free.setdefault(key, [])
            if len(free) < self.keep:
                free.append(base)


_POOL = _Pool()


def empty(shape: tuple[int, ...], dtype: torch.dtype, shared: bool = False) -> torch.Tensor:
    """An uninitialised contiguous tensor; in shared memory when ``shared``."""
    nbytes = math.prod(shape) * dtype.itemsize
    if shared:
        storage = torch.UntypedStorage._new_shared(nbytes)  # what default_collate uses in workers
        return torch.empty(0, dtype=dtype).set_(storage, 0, shape)
    if nbytes < MIN_POOLED_BYTES:
        return torch.empty(shape, dtype=dtype)
    return _POOL.take(shape, dtype)
