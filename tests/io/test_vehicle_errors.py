"""MAVSDK's plugin errors carry their reason in the public ``result`` attribute."""

from __future__ import annotations

import asyncio

import pytest
from mavsdk.plugins.action.action import ActionError, ActionResult
from mavsdk.plugins.offboard.offboard import OffboardError, OffboardResult

from mexgen_gcs.errors import VehicleError
from mexgen_gcs.io.vehicle import MavsdkVehicle, mavsdk_reason


def test_the_reason_is_the_result_name() -> None:
    assert mavsdk_reason(ActionError(ActionResult.COMMAND_DENIED, "arm()")) == "COMMAND_DENIED"
    assert mavsdk_reason(OffboardError(OffboardResult.NO_SETPOINT_SET, "start()")) == (
        "NO_SETPOINT_SET")
    assert mavsdk_reason(RuntimeError("socket closed")) == "socket closed"


async def test_a_denied_command_is_a_vehicle_error_naming_it() -> None:
    async def denied() -> None:
        raise ActionError(ActionResult.COMMAND_DENIED, "arm()")

    with pytest.raises(VehicleError, match="COMMAND_DENIED"):
        await MavsdkVehicle()._call("arm", denied())
    await asyncio.sleep(0)
