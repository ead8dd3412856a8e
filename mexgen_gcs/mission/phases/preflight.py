"""Preflight: connect, wait for health, check the vehicle's PX4 safety parameters, take the
clock from the vehicle, check home, wait for the radio, look at the fence already on the
vehicle, upload ours. Safe action: nothing is armed; the mission ends on the ground. Refusals
for the vehicle's set-up (unsafe parameters, a fence the vehicle refused when one is required,
another station's fence we may not replace) end with exit 2 and a message on stderr.

Frames: horizontal ENU metres about the mission home; the vehicle's home (HOME_POSITION) is
compared with the mission's horizontally and, when ``home.alt_m`` is given, in altitude AMSL.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import sys
from collections.abc import Callable

import numpy as np

from mexgen_gcs.config.px4_params import PARAMS as PX4_PARAMS
from mexgen_gcs.config.px4_params import evaluate as evaluate_params
from mexgen_gcs.errors import VehicleError
from mexgen_gcs.io.vehicle import wait_until
from mexgen_gcs.mission.context import MissionContext
from mexgen_gcs.mission.phases.common import supervised
from mexgen_gcs.mission.state import EndReason, MissionEnd, MissionState, ReturnAction
from mexgen_gcs.mission.warmup import warm_up


def _refuse(ctx: MissionContext, reason: EndReason, **fields: object) -> MissionEnd:
    ctx.set_end(reason)
    ctx.event("preflight_failed", level=logging.ERROR, reason=reason, **fields)
    return MissionEnd(reason, ReturnAction.NONE)


def warn_operator(ctx: MissionContext, kind: str, text: str, *, standing: str | None = None,
                  **fields: object) -> None:
    """A warning the operator must see: a `warning` record and event, a line on stderr (if it
    still works) and, with `standing`, a line in the UI's warnings for the rest of the flight."""
    ctx.warn(kind, text, standing=standing, **fields)
    _say(f"WARNING: {text}")


def _say(text: str) -> None:
    with contextlib.suppress(OSError, ValueError):
        print(text, file=sys.stderr, flush=True)


async def run(ctx: MissionContext, start_telemetry: Callable[[], None]) -> None:
    """The checks, interruptible: a stop request or a fault anywhere ends them at once."""
    await supervised(ctx, _checks(ctx, start_telemetry))


async def _checks(ctx: MissionContext, start_telemetry: Callable[[], None]) -> None:
    ctx.phase = "preflight"
    ctx.state = MissionState.CONNECTING
    # compile (or load from the cache) every kernel now: a compile in flight would stop the
    # loop and the setpoint stream (mission.warmup)
    seconds = await asyncio.to_thread(warm_up, ctx.mission)
    ctx.event("kernels_ready", seconds=round(seconds, 2))
    ctx.event("connecting", url=ctx.connect_url)
    try:
        await ctx.vehicle.connect(ctx.connect_url, ctx.opt.connect_timeout_s)
    except VehicleError as exc:
        ctx.error = str(exc)
        raise _refuse(ctx, EndReason.VEHICLE_ERROR, error=str(exc)) from None
    start_telemetry()
    ctx.state = MissionState.PREFLIGHT
    try:
        await ctx.vehicle.wait_ready(ctx.opt.ready_timeout_s)
    except VehicleError as exc:
        ctx.error = str(exc)
        raise _refuse(ctx, EndReason.VEHICLE_NOT_READY, error=str(exc)) from None
    tel = ctx.vehicle.hub.latest
    ctx.event("vehicle_ready", lat=tel.lat_deg, lon=tel.lon_deg, mode=tel.flight_mode,
              home_alt_amsl_m=tel.home_abs_alt_m)
    await check_params(ctx)
    await sync_clock(ctx)
    check_home(ctx)
    await wait_for_radio(ctx)
    if ctx.mission.safety.upload_geofence:
        await check_existing_fence(ctx)
        await upload_geofence(ctx)
    if ctx.stop is not None:
        raise _refuse(ctx, ctx.stop.reason, armed=False)


async def sync_clock(ctx: MissionContext) -> None:
    """Wait (bounded) until the mission clock follows the vehicle's SYSTEM_TIME; then the
    mission's time origin restarts on it. Without vehicle time the wall clock stays."""
    clock = ctx.clock
    synced = getattr(clock, "synced", None)
    if synced is None:  # a plain wall clock
        return
    loop = asyncio.get_running_loop()
    deadline = loop.time() + ctx.opt.clock_wait_s
    while not clock.synced and loop.time() < deadline:  # type: ignore[attr-defined]
        await asyncio.sleep(0.05)
    info = clock.describe()  # type: ignore[attr-defined]
    if clock.synced:  # type: ignore[attr-defined]
        ctx.event("clock", **info)
    else:
        warn_operator(ctx, "clock_fallback", "no SYSTEM_TIME from the vehicle within "
                      f"{ctx.opt.clock_wait_s:.0f} s: the mission runs on the wall clock "
                      f"(rate {clock.rate:g})", **info)
    now = clock.now()
    ctx.t_start = now
    ctx.last_radio_t = max(ctx.last_radio_t, now) if math.isfinite(ctx.last_radio_t) else now


def check_home(ctx: MissionContext) -> None:
    """Compare the vehicle's home with the mission's: refuse beyond home_max_distance_m
    outside the area, warn beyond home_mismatch_warn_m / home_alt_mismatch_warn_m."""
    s = ctx.mission.safety
    tel = ctx.vehicle.hub.latest
    e, n, _ = ctx.frame.to_enu(tel.home_lat_deg, tel.home_lon_deg)
    home_en = np.array([float(e), float(n)])
    offset_m = float(np.hypot(*home_en))
    outside_m = float(ctx.area.distance_outside_m(home_en))
    if not (math.isfinite(outside_m) and outside_m <= s.home_max_distance_m):
        raise _refuse(ctx, EndReason.HOME_TOO_FAR_FROM_AREA,
                      distance_outside_area_m=round(outside_m, 1),
                      from_mission_home_m=round(offset_m, 1), limit_m=s.home_max_distance_m)
    if offset_m > s.home_mismatch_warn_m:
        warn_operator(ctx, "home_mismatch", f"the vehicle's home is {offset_m:.0f} m from the "
                      f"mission's home (warn beyond {s.home_mismatch_warn_m:g} m); the area "
                      "stays where the mission file puts it", distance_m=round(offset_m, 1))
    alt = ctx.mission.home.alt_m
    if alt is not None and math.isfinite(tel.home_abs_alt_m) and (
            abs(tel.home_abs_alt_m - alt) > s.home_alt_mismatch_warn_m):
        warn_operator(ctx, "home_alt_mismatch", f"home.alt_m = {alt:g} m but the vehicle's "
                      f"home is at {tel.home_abs_alt_m:.1f} m AMSL (warn beyond "
                      f"{s.home_alt_mismatch_warn_m:g} m); heights are taken from the vehicle",
                      mission_alt_m=alt, vehicle_alt_m=round(tel.home_abs_alt_m, 1))
    ctx.event("home_checked", distance_outside_area_m=round(outside_m, 1),
              from_mission_home_m=round(offset_m, 1))


async def wait_for_radio(ctx: MissionContext) -> None:
    """A receiver heartbeat no older than receiver.heartbeat_timeout_s (mission time): the
    radio is alive now, not just once."""
    ctx.event("waiting_for_radio")
    fresh_s = ctx.mission.receiver.heartbeat_timeout_s
    try:
        await wait_until(lambda: ctx.clock.now() - ctx.last_heartbeat_t <= fresh_s,
                         ctx.opt.radio_wait_s, "radio heartbeat")
    except VehicleError:
        raise _refuse(ctx, EndReason.NO_RADIO, error=f"no radio heartbeat within "
                      f"{ctx.opt.radio_wait_s:.0f} s on {ctx.mission.receiver.listen}") from None
    ctx.event("radio_ok")


async def check_params(ctx: MissionContext) -> None:
    """Read the PX4 parameters that decide what the vehicle does when this GCS fails, judge
    them against the mission (config.px4_params) and refuse an unsafe set (exit 2) unless
    accepted (safety.accept_px4_params, --accept-unsafe-params)."""
    try:
        values = await ctx.vehicle.read_params([(d.name, d.kind) for d in PX4_PARAMS])
    except VehicleError as exc:
        warn_operator(ctx, "vehicle_params_not_read", f"the vehicle's parameters could not be "
                      f"read ({exc}); its failsafes are unchecked", error=str(exc))
        return
    report = evaluate_params(ctx.mission, values)
    ctx.event("vehicle_params", values={k: v for k, v in values.items() if v is not None},
              refused=[r.name for r in report.refused],
              accepted=[r.name for r in report.rows if r.accepted])
    for row in report.warnings:
        warn_operator(ctx, "vehicle_param", f"PX4 {row.name} = {row.shown_value()}: "
                      f"{row.problem}{' (accepted)' if row.accepted else ''}", param=row.name)
    if report.refused:
        _say(report.table())
        for row in report.refused:
            _say(f"REFUSED: PX4 {row.name} = {row.shown_value()}: {row.problem}")
        names = [r.name for r in report.refused]
        _say(f"Set them on the vehicle, or accept them knowingly with safety.accept_px4_params "
             f"or --accept-unsafe-params {','.join(names)}; nothing was armed.")
        raise _refuse(ctx, EndReason.VEHICLE_PARAMS_UNSAFE, params=names,
                      problems=[f"{r.name} = {r.shown_value()}: {r.problem}"
                                for r in report.refused])


async def check_existing_fence(ctx: MissionContext) -> None:
    """Another station (the pilot's QGroundControl) may have put a fence on the vehicle; ours
    replaces it. Show it, and refuse (exit 2) unless safety.replace_existing_geofence."""
    try:
        shapes = await ctx.vehicle.download_geofence()
    except VehicleError as exc:
        warn_operator(ctx, "geofence_not_read", f"the fence on the vehicle could not be read "
                      f"({exc}); ours will replace whatever is there", error=str(exc))
        return
    if not shapes:
        return
    shown = [[(round(lat, 7), round(lon, 7)) for lat, lon in shape] for shape in shapes]
    if len(shapes) == 1 and _same_fence(ctx, shapes[0], our_fence_en_m(ctx)):
        ctx.event("geofence_on_vehicle_is_ours", vertices=len(shapes[0]))
        return  # this mission's own fence from an earlier flight: replaced without asking
    text = (f"the vehicle already holds a geofence of {len(shapes)} shape(s) (first: "
            + "; ".join(f"{lat:.6f}, {lon:.6f}" for lat, lon in shown[0][:6])
            + (" ..." if len(shown[0]) > 6 else "") + ")")
    if ctx.mission.safety.replace_existing_geofence:
        warn_operator(ctx, "geofence_replaced", f"{text}; replacing it with ours "
                      "(safety.replace_existing_geofence)", shapes=shown)
        return
    _say(f"REFUSED: {text}. It may be the pilot's: agree whose fence flies, then set "
         "safety.replace_existing_geofence: true (ours replaces it) or clear it; nothing was "
         "armed.")
    raise _refuse(ctx, EndReason.GEOFENCE_ON_VEHICLE, shapes=shown)


async def upload_geofence(ctx: MissionContext) -> None:
    """The convex hull of the area and both homes, pushed out by geofence_margin_m. A refusal
    ends the mission before arming (exit 2) with safety.require_geofence, else it is a standing
    warning."""
    margin = ctx.mission.safety.geofence_margin_m
    fence = our_fence_en_m(ctx)
    lat, lon, _ = ctx.frame.to_geodetic(fence[:, 0], fence[:, 1])
    try:
        await ctx.commander.upload_geofence(list(zip(lat.tolist(), lon.tolist(), strict=True)))
        ctx.event("geofence_uploaded", vertices=len(fence), margin_m=margin,
                  fence_en_m=np.round(fence, 1))
    except VehicleError as exc:
        if ctx.mission.safety.require_geofence:
            _say(f"REFUSED: the vehicle did not take the geofence ({exc}) and "
                 "safety.require_geofence is true; nothing was armed.")
            raise _refuse(ctx, EndReason.GEOFENCE_REFUSED, error=str(exc)) from None
        warn_operator(ctx, "geofence_not_accepted", f"the vehicle did not take the geofence "
                      f"({exc}); flying without it", standing="NO GEOFENCE ON THE VEHICLE",
                      error=str(exc))


SAME_FENCE_M = 25.0
"""A fence on the vehicle whose vertices are all this close to ours is this mission's own."""


def our_fence_en_m(ctx: MissionContext) -> np.ndarray:
    """The fence this mission uploads, (K, 2) ENU metres: the convex hull of the area and both
    homes, pushed out by geofence_margin_m."""
    tel = ctx.vehicle.hub.latest
    e, n, _ = ctx.frame.to_enu(tel.home_lat_deg, tel.home_lon_deg)
    homes = np.array([[0.0, 0.0], [float(e), float(n)]])
    return ctx.area.fence_polygon(ctx.mission.safety.geofence_margin_m, homes)


def _same_fence(ctx: MissionContext, shape: list[tuple[float, float]], ours: np.ndarray
                ) -> bool:
    """Same vertex count and every vertex of `shape` within SAME_FENCE_M of ours, in order
    (from any starting vertex): the fence an earlier flight of this mission uploaded."""
    if len(shape) != len(ours):
        return False
    lat = np.array([p[0] for p in shape])
    lon = np.array([p[1] for p in shape])
    e, n, _ = ctx.frame.to_enu(lat, lon)
    theirs = np.column_stack([e, n])
    for shift in range(len(ours)):
        if np.all(np.hypot(*(np.roll(theirs, shift, axis=0) - ours).T) <= SAME_FENCE_M):
            return True
    return False
