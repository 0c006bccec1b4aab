"""Fixtures shared by the model tests."""

from __future__ import annotations

import shutil

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


@pytest.fixture(scope="session")
def probed_run(tiny_run, tiny_dataset_master, tmp_path_factory):
    """A copy of the tiny run with a real physics probe in RUN/probe (two tiny epochs): what the
    planner loads. Shared: flights read it, none writes to it."""
    from orbitmodel.config import get_preset
    from orbitmodel.probe.train import ProbeRequest, train_probe

    run = tmp_path_factory.mktemp("probed") / "tiny"
    shutil.copytree(tiny_run, run)
    train_probe(ProbeRequest(run=run, dataset=str(tiny_dataset_master), recipe=get_preset("tiny").probe, device="cpu"))
    return run
