"""Fixtures for the UI tests (builders and fakes are in ui_helpers)."""

from __future__ import annotations

import pytest

from mexgen_gcs.io.snapshot import MissionSnapshot
from tests.ui.ui_helpers import make_snapshot


@pytest.fixture
def snapshot() -> MissionSnapshot:
    return make_snapshot()
