"""Fixtures that run the real simulator as a subprocess on free UDP ports.

``sim_factory(mission_path, **options)`` starts ``python -m sim`` and waits for its ready
line; every process started is stopped with SIGTERM at teardown, and the test fails unless it
exits cleanly (code 0).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.sim.mav_helpers import open_client
from tests.sim.sim_helpers import DEMO_MISSION, SimFactory, SimProcess, free_udp_port, start_sim


@pytest.fixture
def sim_factory(tmp_path: Path) -> Iterator[SimFactory]:
    started: list[SimProcess] = []

    def factory(mission: Path = DEMO_MISSION, *, mavlink_port: int | None = None,
                radio_port: int | None = None, speedup: float = 1.0, sysid: int = 1,
                extra: list[str] | None = None) -> SimProcess:
        truth_dir = tmp_path / f"sim{len(started)}"
        sim = start_sim(mission, truth_dir,
                        mavlink_port=mavlink_port if mavlink_port else free_udp_port(),
                        radio_port=radio_port if radio_port else free_udp_port(),
                        speedup=speedup, sysid=sysid, extra=extra)
        started.append(sim)
        return sim

    yield factory
    codes = []
    for sim in started:
        was_running = sim.alive()
        code = sim.stop()
        codes.append((was_running, code, "".join(sim.stderr_lines)[-1500:]))
    for was_running, code, err in codes:
        assert code == 0, f"simulator exited with {code} (running at teardown: {was_running}):" \
                          f"\n{err}"


@pytest.fixture
def client() -> Iterator[Any]:
    """A pymavlink mavutil client on a free port; pass its port to the simulator."""
    conn = open_client()
    yield conn
    conn.close()
