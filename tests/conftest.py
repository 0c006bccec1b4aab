"""Shared fixtures: tiny datasets made by the real generator (64 px, a handful of episodes)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
from tiny import tiny_config

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("HF_DATASETS_OFFLINE", "1")
os.environ.setdefault("TOKENIZERS_PARALLELISM", "false")


@pytest.fixture(scope="session")
def tiny_dataset_master(tmp_path_factory) -> Path:
    """A 6-episode, 64 px dataset generated once per session (do not modify it)."""
    from orbitdata.viz import overview_figure
    from orbitdata.write.generate import generate

    out = tmp_path_factory.mktemp("tiny") / "orbit"
    generate(out, tiny_config(), workers=1, figure=overview_figure)
    return out


@pytest.fixture
def tiny_dataset(tiny_dataset_master, tmp_path) -> Path:
    """A private copy of the tiny dataset that a test may corrupt or modify."""
    dst = tmp_path / "orbit"
    shutil.copytree(tiny_dataset_master, dst)
    return dst
