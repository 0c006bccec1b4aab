"""Fixtures shared by the model tests."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def tiny_run(tiny_dataset_master, tmp_path_factory):
    """A Stage I run of the tiny preset, two steps on the tiny dataset. Shared: copy it before
    adding to it (a probe, a resumed run)."""
    from orbitmodel.config import get_preset
    from orbitmodel.train.stage1 import Stage1Request, train_world_model

    out = tmp_path_factory.mktemp("stage1") / "run"
    train_world_model(
        Stage1Request(
            dataset=str(tiny_dataset_master), preset=get_preset("tiny").with_train(max_steps=2), out=out, device="cpu"
        )
    )
    return out
