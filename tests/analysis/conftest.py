"""Flight logs for the analysis tests, flown once per session by the real simulator (SITL at
speedup 20 on free loopback ports): a short demo flight with MexGen that ends on the mission
time limit (some tags localised, a failsafe RTL), and a shorter one with PIM for comparisons.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from mexgen_gcs.config import CLASSIC_ESTIMATOR
from mexgen_gcs.mission.controller import ControllerOptions
from mexgen_gcs.mission.run import SitlPorts, run_sitl

MISSIONS = Path(__file__).resolve().parents[2] / "missions"
SPEEDUP = 20.0


def _fly(base: Path, method: str, seed: int, max_time_s: float) -> Path:
    result = run_sitl(MISSIONS / "demo.yaml", seed=seed, speedup=SPEEDUP, method=method,
                      ports=SitlPorts.free(), log_dir=base,
                      # the classic estimator: these flights test the analysis, and it
                      # localises within the short flights; the estimator has its own tests
                      overrides={"safety.max_mission_time_s": max_time_s,
                                 **CLASSIC_ESTIMATOR},
                      options=ControllerOptions(print_progress=False))
    assert result.log_dir is not None
    return Path(result.log_dir)


@pytest.fixture(scope="session")
def demo_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Demo, MexGen, 150 s mission time: the first tags localised, then an RTL on time."""
    return _fly(tmp_path_factory.mktemp("flights"), "mexgen", 5, 150.0)


@pytest.fixture(scope="session")
def pim_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Demo, PIM, 60 s mission time."""
    return _fly(tmp_path_factory.mktemp("flights-pim"), "pim", 6, 60.0)


def _namespace(**fields: Any) -> argparse.Namespace:
    base: dict[str, Any] = {"log": None, "out": None, "truth": None, "calibrate": None,
                            "tag_position": None, "export": False, "method": None,
                            "headless": True, "speedup": 1.0, "seed": None}
    base.update(fields)
    return argparse.Namespace(**base)


@pytest.fixture
def make_args() -> Callable[..., argparse.Namespace]:
    """Arguments as the full command line parses them, with every analysis flag (the handlers
    read flags with defaults, so this works before and after the parser grows them)."""
    return _namespace


@pytest.fixture(scope="session")
def missions_dir() -> Path:
    return MISSIONS
