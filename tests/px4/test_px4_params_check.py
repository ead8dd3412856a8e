"""`mexgen-gcs check --connect` against real PX4 SITL (SIH): the safety-parameter table is
read from the real parameter server, and the SIH airframe's own data-link-loss setting
(NAV_DLL_ACT 0, kept from the firmware default) is refused with the parameter named."""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.px4.conftest import Px4Factory
from tests.sim.sim_helpers import DEMO_MISSION

pytestmark = pytest.mark.px4

HOME = (-34.9212, 138.6011, 0.0)  # the demo mission's home


def check(url: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "mexgen_gcs", "check", str(DEMO_MISSION), "--connect", url],
        capture_output=True, text=True, timeout=120)


def test_check_connect_prints_px4s_parameters(px4_factory: Px4Factory) -> None:
    # NAV_DLL_ACT 2 (Return), as the field guide asks; the SIH airframe keeps the firmware's 0
    px4 = px4_factory(speed_factor=1.0, home=HOME, late_params={"NAV_DLL_ACT": 2})
    proc = check(px4.mavsdk_url)
    print(proc.stdout)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    for name in ("COM_OBL_RC_ACT", "NAV_DLL_ACT", "GF_ACTION", "RTL_RETURN_ALT",
                 "MPC_XY_VEL_MAX"):
        assert name in proc.stdout
    assert "NAV_DLL_ACT       2 Return" in proc.stdout


def test_check_connect_refuses_sihs_own_datalink_setting(px4_factory: Px4Factory) -> None:
    px4 = px4_factory(speed_factor=1.0, home=HOME, params={"NAV_DLL_ACT": 0})
    proc = check(px4.mavsdk_url)
    print(proc.stdout)
    assert proc.returncode == 2
    assert "REFUSED NAV_DLL_ACT = 0 Disabled" in proc.stdout
    assert "set NAV_DLL_ACT = 2 (Return)" in proc.stdout
