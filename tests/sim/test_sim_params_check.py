"""The vehicle's safety parameters: the simulator serves them with PX4 SITL's defaults and types
over the MAVLink PARAM protocol (``--param NAME=VALUE`` sets them), and ``mexgen-gcs check
--connect`` reads them through MAVSDK, prints the table beside the mission's needs and refuses an
unsafe set with exit 2 naming the parameter and a safe value."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from pymavlink import mavutil

from mexgen_gcs.config import load_mission
from mexgen_gcs.config.px4_params import NAMES, evaluate
from sim.params import SPECS, int_from_wire, int_to_wire, parse_param_flag
from tests.sim.mav_helpers import start, wait_for
from tests.sim.sim_helpers import DEMO_MISSION, REPO, SimFactory, free_udp_port

M = mavutil.mavlink
SITL_DEFAULTS = {s.name: s.default for s in SPECS}

pytestmark = pytest.mark.e2e


def run_check(*args: str, timeout_s: float = 90.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "mexgen_gcs", "check", *args],
                          capture_output=True, text=True, timeout=timeout_s, cwd=REPO)


def test_sim_serves_every_checked_parameter_with_px4_types(sim_factory: SimFactory,
                                                           client: Any) -> None:
    start(sim_factory, client, extra=["--param", "NAV_DLL_ACT=3"])
    for name in NAMES:
        client.mav.param_request_read_send(1, 1, name.encode(), -1)
        msg = wait_for(client, "PARAM_VALUE", lambda m, n=name: m.param_id == n)
        if msg.param_type == M.MAV_PARAM_TYPE_INT32:  # PX4's bytewise encoding
            value = float(int_from_wire(msg.param_value))
        else:
            assert msg.param_type == M.MAV_PARAM_TYPE_REAL32
            value = msg.param_value
        expected = 3.0 if name == "NAV_DLL_ACT" else SITL_DEFAULTS[name]
        assert value == pytest.approx(expected), name
    # an INT32 PARAM_SET, bytewise
    client.mav.param_set_send(1, 1, b"GF_ACTION", int_to_wire(5), M.MAV_PARAM_TYPE_INT32)
    echo = wait_for(client, "PARAM_VALUE", lambda m: m.param_id == "GF_ACTION")
    assert echo.param_type == M.MAV_PARAM_TYPE_INT32 and int_from_wire(echo.param_value) == 5


def test_param_flag_is_checked() -> None:
    assert parse_param_flag("RTL_RETURN_ALT=60") == ("RTL_RETURN_ALT", 60.0)
    for bad in ("RTL_RETURN_ALT", "NOPE=1", "GF_ACTION=high", "GF_ACTION=nan"):
        with pytest.raises(ValueError):
            parse_param_flag(bad)


def test_sitl_defaults_pass_the_demo() -> None:
    report = evaluate(load_mission(DEMO_MISSION), SITL_DEFAULTS)
    assert report.refused == ()
    assert {r.name for r in report.warnings} == {"COM_OBL_RC_ACT", "RTL_RETURN_ALT"}


def test_a_low_search_says_where_a_return_flies() -> None:
    """With flight.min_alt_m the search may be below RTL_RETURN_ALT: PX4's return then climbs
    to it, or keeps the search's height when that is higher; the warning gives that height."""
    mission = load_mission(DEMO_MISSION).model_copy(update={"flight": load_mission(
        DEMO_MISSION).flight.model_copy(update={"min_alt_m": 20.0})})
    (rtl,) = [r for r in evaluate(mission, SITL_DEFAULTS).warnings if r.name == "RTL_RETURN_ALT"]
    assert "flight.min_alt_m 20 m" in rtl.problem and "flies home at 30 m" in rtl.problem
    (rtl,) = [r for r in evaluate(mission, {**SITL_DEFAULTS, "RTL_RETURN_ALT": 16.0}).warnings
              if r.name == "RTL_RETURN_ALT"]
    assert "flies home at 20 m" in rtl.problem


def test_check_connect_prints_the_table(sim_factory: SimFactory) -> None:
    port = free_udp_port()
    sim_factory(mavlink_port=port)
    proc = run_check(str(DEMO_MISSION), "--connect", f"udpin://127.0.0.1:{port}")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    out = proc.stdout
    assert "PX4 parameters" in out
    for name in NAMES:
        assert name in out, name
    assert "NAV_DLL_ACT       2 Return" in out
    assert "GF_ACTION         2 Hold" in out
    assert "Geofence on the vehicle: none." in out
    assert "REFUSED" not in out


def test_check_connect_refuses_an_unsafe_set(sim_factory: SimFactory, tmp_path: Path) -> None:
    port = free_udp_port()
    sim_factory(mavlink_port=port, extra=["--param", "NAV_DLL_ACT=0", "--param",
                                          "COM_OBL_RC_ACT=6", "--param", "MPC_XY_VEL_MAX=8"])
    url = f"udpin://127.0.0.1:{port}"
    proc = run_check(str(DEMO_MISSION), "--connect", url)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "REFUSED NAV_DLL_ACT = 0 Disabled" in proc.stdout
    assert "set NAV_DLL_ACT = 2 (Return)" in proc.stdout
    assert "REFUSED COM_OBL_RC_ACT = 6 Terminate" in proc.stdout
    assert "set COM_OBL_RC_ACT = 3 (Return)" in proc.stdout
    assert "REFUSED MPC_XY_VEL_MAX = 8" in proc.stdout
    assert "refused: the vehicle's parameters are unsafe" in proc.stderr
    # accepted knowingly: the flag for one, the mission key for the others
    text = DEMO_MISSION.read_text().replace(
        "safety:\n", "safety:\n  accept_px4_params: [COM_OBL_RC_ACT, MPC_XY_VEL_MAX]\n", 1)
    mission = tmp_path / "accepting.yaml"
    mission.write_text(text, "utf-8")
    proc = run_check(str(mission), "--connect", url, "--accept-unsafe-params", "NAV_DLL_ACT")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "accepted (unsafe)" in proc.stdout and "REFUSED" not in proc.stdout


def test_check_connect_without_a_vehicle_fails() -> None:
    port = free_udp_port()
    proc = run_check(str(DEMO_MISSION), "--connect", f"udpin://127.0.0.1:{port}",
                     "--connect-timeout", "2")
    assert proc.returncode == 1
    assert "no autopilot heard" in proc.stderr


def test_a_flight_refuses_unsafe_params_before_arming(tmp_path: Path,
                                                      capfd: pytest.CaptureFixture[str]) -> None:
    from mexgen_gcs.io.flightlog import read_flight_log
    from mexgen_gcs.mission.run import SitlPorts, run_sitl

    result = run_sitl(DEMO_MISSION, seed=3, speedup=5.0, ports=SitlPorts.free(),
                      log_dir=tmp_path, sim_args=["--param", "GF_ACTION=1"])
    assert result.end_reason == "vehicle_params_unsafe" and result.exit_code == 2
    assert "REFUSED: PX4 GF_ACTION = 1 Warning" in capfd.readouterr().err
    kinds = [r.get("kind") for r in read_flight_log(result.log_dir).records]
    assert "vehicle_params" in kinds and "armed" not in kinds


def test_accept_flag_reaches_the_mission() -> None:
    import argparse

    from mexgen_gcs.ui.commands import _accept_params

    mission = load_mission(DEMO_MISSION)
    args = argparse.Namespace(accept_unsafe_params=frozenset({"GF_ACTION", "NAV_DLL_ACT"}))
    assert _accept_params(mission, args).safety.accept_px4_params == ("GF_ACTION",
                                                                      "NAV_DLL_ACT")
    assert _accept_params(mission, argparse.Namespace()) is mission
