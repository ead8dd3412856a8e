"""`mexgen-gcs check MISSION --connect URL`: the vehicle's safety parameters and fence, read
over MAVLink before a field day and judged against the mission (config.px4_params).

Connects through the same MAVSDK adapter as a flight (io.vehicle), reads the parameters of
`config.px4_params.PARAMS`, prints the table beside what the mission needs, lists the
geofence already on the vehicle, and returns the exit code: 0 when the set is safe (warnings
allowed), 2 when a refusal is not accepted (each names the parameter and a safe value), 1 when
the vehicle cannot be reached. Positions are WGS84 degrees.
"""

from __future__ import annotations

import asyncio
import sys
from collections.abc import Iterable
from typing import TextIO

from mexgen_gcs.config.mission import Mission
from mexgen_gcs.config.px4_params import PARAMS, ParamReport, evaluate
from mexgen_gcs.errors import VehicleError
from mexgen_gcs.io.vehicle import MavsdkVehicle, Vehicle


async def read_safety_params(vehicle: Vehicle) -> dict[str, float | None]:
    """The parameters config.px4_params judges, from a connected vehicle."""
    return await vehicle.read_params([(d.name, d.kind) for d in PARAMS])


def report_lines(report: ParamReport) -> list[str]:
    """The table and one line per problem, for the terminal."""
    lines = ["PX4 parameters (the vehicle's failure behaviour and envelope):", report.table()]
    refused, warned = report.refused, report.warnings
    for text in report.problems()[:len(refused)]:
        lines.append(f"REFUSED {text}")
    for text in report.problems()[len(refused):len(refused) + len(warned)]:
        lines.append(f"warning {text}")
    if refused:
        names = ", ".join(r.name for r in refused)
        lines.append(f"{len(refused)} unsafe parameter(s): {names}. Set them on the vehicle "
                     "(e.g. in QGroundControl, Vehicle Setup > Parameters), or accept them "
                     "knowingly with safety.accept_px4_params: [" + names + "] or "
                     "--accept-unsafe-params " + names.replace(", ", ","))
    return lines


def fence_lines(polygons: Iterable[list[tuple[float, float]]]) -> list[str]:
    shapes = list(polygons)
    if not shapes:
        return ["Geofence on the vehicle: none."]
    out = [f"Geofence on the vehicle: {len(shapes)} shape(s):"]
    for i, shape in enumerate(shapes):
        pts = "; ".join(f"{lat:.6f}, {lon:.6f}" for lat, lon in shape[:8])
        more = f"; ... ({len(shape)} vertices)" if len(shape) > 8 else ""
        out.append(f"  [{i}] {pts}{more}")
    return out


async def _check(mission: Mission, url: str, accepted: frozenset[str], timeout_s: float,
                 out: TextIO) -> int:
    vehicle = MavsdkVehicle()
    try:
        await vehicle.connect(url, timeout_s)
        values = await read_safety_params(vehicle)
        try:
            fence = await vehicle.download_geofence()
            fence_text = fence_lines(fence)
        except VehicleError as exc:
            fence_text = [f"Geofence on the vehicle: not read ({exc})"]
    finally:
        await vehicle.close()
    report = evaluate(mission, values, accepted)
    for line in [*report_lines(report), *fence_text]:
        print(line, file=out)
    return 2 if report.refused else 0


def check_vehicle(mission: Mission, url: str, accepted: frozenset[str],
                  timeout_s: float = 30.0, out: TextIO = sys.stdout) -> int:
    """Exit code of `check --connect` (see the module docstring); VehicleError when the vehicle
    cannot be reached."""
    return asyncio.run(_check(mission, url, accepted, timeout_s, out))
