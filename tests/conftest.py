"""Shared fixtures: tiny datasets made by the real generator (64 px, a handful of episodes)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
from publish.hub_server import TOKEN, HubServer
from tiny import dynamic_config, tiny_config

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


@pytest.fixture(scope="session")
def dynamic_master(tmp_path_factory) -> Path:
    """A 6-episode, 32 px dataset of the dynamic tier generated once per session (do not modify it)."""
    from orbitdata.viz import overview_figure
    from orbitdata.write.generate import generate

    out = tmp_path_factory.mktemp("dynamic") / "orbit"
    generate(out, dynamic_config(), workers=1, figure=overview_figure)
    return out


@pytest.fixture
def tiny_dataset(tiny_dataset_master, tmp_path) -> Path:
    """A private copy of the tiny dataset that a test may corrupt or modify."""
    dst = tmp_path / "orbit"
    shutil.copytree(tiny_dataset_master, dst)
    return dst


# ---- a local test Hub (tests/publish/hub_server.py) and the real client pointed at it ----------
@pytest.fixture
def hub():
    with HubServer(TOKEN) as server:
        yield server


@pytest.fixture
def hub_client(hub, monkeypatch, tmp_path):
    """The real huggingface_hub client in this process, talking to the test Hub with LFS (no Xet),
    with a cache of its own (downloads land in tmp_path/hf-cache).

    The client reads HF_ENDPOINT and friends once, at import, so they are patched on its
    constants module; the token comes from HF_TOKEN like it would for a user.
    """
    from huggingface_hub import constants

    monkeypatch.setattr(constants, "ENDPOINT", hub.url)
    monkeypatch.setattr(constants, "HUGGINGFACE_CO_URL_TEMPLATE", hub.url + "/{repo_id}/resolve/{revision}/{filename}")
    monkeypatch.setattr(constants, "HF_HUB_OFFLINE", False)
    monkeypatch.setattr(constants, "HF_HUB_DISABLE_XET", True)
    monkeypatch.setattr(constants, "HF_TOKEN_PATH", str(tmp_path / "no-stored-token"))
    monkeypatch.setattr(constants, "HF_HUB_CACHE", str(tmp_path / "hf-cache"))
    monkeypatch.setenv("HF_TOKEN", TOKEN)
    return hub
