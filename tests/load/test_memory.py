"""Recycled batch memory: a buffer is reused only once no tensor (or view) uses it any more."""

from __future__ import annotations

import torch

from orbitdata.load.memory import MIN_POOLED_BYTES, empty

SHAPE = (16, MIN_POOLED_BYTES // 16)  # uint8: just large enough to be pooled


def test_memory_in_use_is_never_handed_out_again():
    a = empty(SHAPE, torch.uint8)
    a.fill_(1)
    b = empty(SHAPE, torch.uint8)
    assert a.data_ptr() != b.data_ptr()
    view, ptr = a[3], a.data_ptr()
    del a
    c = empty(SHAPE, torch.uint8)
    c.fill_(2)
    assert c.data_ptr() != ptr and bool((view == 1).all())  # a view keeps the batch alive
    del view
    d = empty(SHAPE, torch.uint8)
    assert d.data_ptr() == ptr  # recycled once nothing uses it
    assert bool((b.fill_(3) == 3).all()) and bool((c == 2).all())


def test_small_and_shared_buffers_are_plain_tensors():
    small = empty((4, 5), torch.float32)
    assert small.shape == (4, 5) and small.dtype == torch.float32
    shared = empty((3, 7), torch.int64, shared=True)
    assert shared.is_shared() and shared.shape == (3, 7) and shared.is_contiguous()
