"""Tests against real PX4 SITL (SIH): marker ``px4``, skipped unless a PX4 build is found.

Run them with ``python -m pytest -m px4 tests/px4`` (PX4_SITL_BIN=/path/to/bin/px4 if it is not
at the default build path). Each test starts its own PX4 on free ports and removes it after.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import ExitStack

import pytest

from tests.px4.px4_sitl import Px4Sitl, find_px4, px4_sih


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if find_px4() is not None:
        return
    skip = pytest.mark.skip(reason="no PX4 SITL build (set PX4_SITL_BIN)")
    for item in items:
        if "px4" in item.keywords:
            item.add_marker(skip)


Px4Factory = Callable[..., Px4Sitl]


@pytest.fixture
def px4_factory() -> Iterator[Px4Factory]:
    """``px4_factory(speed_factor=4.0, home=(lat, lon, alt), params={...})``: a ready PX4,
    stopped and deleted (working directory, parameters, ulog) when the test ends."""
    with ExitStack() as stack:
        yield lambda **kw: stack.enter_context(px4_sih(**kw))
