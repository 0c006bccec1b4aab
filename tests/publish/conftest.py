"""A local test Hub (tests/publish/hub_server.py) and the real client pointed at it."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from hub_server import TOKEN, HubServer  # noqa: E402


@pytest.fixture
def hub():
    with HubServer(TOKEN) as server:
        yield server


@pytest.fixture
def hub_client(hub, monkeypatch, tmp_path):
    """The real huggingface_hub client in this process, talking to the test Hub with LFS (no Xet).

    The client reads HF_ENDPOINT and friends once, at import, so they are patched on its
    constants module; the token comes from HF_TOKEN like it would for a user.
    """
    from huggingface_hub import constants

    monkeypatch.setattr(constants, "ENDPOINT", hub.url)
    monkeypatch.setattr(constants, "HF_HUB_OFFLINE", False)
    monkeypatch.setattr(constants, "HF_HUB_DISABLE_XET", True)
    monkeypatch.setattr(constants, "HF_TOKEN_PATH", str(tmp_path / "no-stored-token"))
    monkeypatch.setenv("HF_TOKEN", TOKEN)
    return hub

