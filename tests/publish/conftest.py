"""The push tests import the test Hub as ``hub_server`` (its fixtures, ``hub`` and ``hub_client``, are
in tests/conftest.py, shared with the model tests)."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
import hub_server  # noqa: E402,F401
