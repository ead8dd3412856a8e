"""Fixtures for the UI tests (builders and fakes are in ui_helpers)."""

from __future__ import annotations

import pytest
from ui_helpers import make_snapshot

from mexgen_gcs.mission.snapshot import MissionSnapshot


@pytest.fixture
def snapshot() -> MissionSnapshot:
    return make_snapshot()
