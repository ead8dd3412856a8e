"""The Vehicle port and its MAVSDK adapter (native asyncio binding, ``mavsdk.asyncio``).

Frames: MAVLink/MAVSDK speak NED (north, east, down) for velocities and compass degrees for
yaw; this module keeps those names (``v_north_m_s``, ``yaw_deg``). Positions are WGS84.

One MAVSDK subscription per telemetry stream, each consumed by one task owned by
``MavsdkVehicle.run_telemetry`` (a TaskGroup) and fanned out as the latest value in a
``TelemetryHub``; readers take immutable ``Telemetry`` snapshots, and listeners registered on
the hub hear every position update, every STATUSTEXT (the autopilot's reasons) and every
SYSTEM_TIME sample (the vehicle's clock), stamped with ``time.monotonic()`` on arrival. An
exception in a listener or a stream ends ``run_telemetry`` (the mission contains it). Every
command is wrapped in a timeout and turns MAVSDK errors into ``VehicleError(call, result)``.

Heights: ``rel_alt_m`` is MAVSDK's ``relative_altitude_m``, height above the vehicle's own home
(HOME_POSITION); ``abs_alt_m`` and ``home_abs_alt_m`` are AMSL.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import json
import logging
import math
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Coroutine, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Protocol

from mexgen_gcs.errors import VehicleError
from mexgen_gcs.io.clock import BootAnchor
from mexgen_gcs.io.mavlink_tap import MavlinkTap, tappable

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class Telemetry:
    """Latest vehicle state; `updated_wall` is the wall time of the last message of any kind."""

    connected: bool = False
    lat_deg: float = math.nan
    lon_deg: float = math.nan
    abs_alt_m: float = math.nan
    rel_alt_m: float = math.nan
    v_north_m_s: float = 0.0
    v_east_m_s: float = 0.0
    v_down_m_s: float = 0.0
    yaw_deg: float = 0.0
    armed: bool = False
    in_air: bool = False
    landed_state: str = "UNKNOWN"
    flight_mode: str = "UNKNOWN"
    battery_percent: float = math.nan
    global_position_ok: bool = False
    home_position_ok: bool = False
    armable: bool = False
    home_lat_deg: float = math.nan
    home_lon_deg: float = math.nan
    home_abs_alt_m: float = math.nan
    updated_wall: float = 0.0

    @property
    def ground_speed_m_s(self) -> float:
        return math.hypot(self.v_north_m_s, self.v_east_m_s)

    @property
    def has_position(self) -> bool:
        return math.isfinite(self.lat_deg) and math.isfinite(self.lon_deg)

    @property
    def has_home(self) -> bool:
        return math.isfinite(self.home_lat_deg) and math.isfinite(self.home_lon_deg)


@dataclass(frozen=True, slots=True)
class StatusText:
    """One STATUSTEXT from the autopilot; `mono_s` is its arrival (time.monotonic)."""

    mono_s: float
    severity: str
    """debug | info | notice | warning | error | critical | alert | emergency."""
    text: str


UpdateListener = Callable[[frozenset[str], Telemetry], None]
StatusListener = Callable[[StatusText], None]
TimeListener = Callable[[float, float], None]
"""(vehicle unix seconds, arrival time.monotonic seconds)."""


class TelemetryHub:
    """Keeps the latest `Telemetry`; writers `update(**fields)`, readers `latest`.

    Listeners (``on_update``, ``on_status_text``, ``on_time``) are called synchronously by
    the writer; an exception in one propagates to the writer (a telemetry stream), which is
    how a broken consumer surfaces instead of being silently skipped.
    """

    def __init__(self) -> None:
        self._state = Telemetry()
        self.messages = 0
        self.statustexts: collections.deque[StatusText] = collections.deque(maxlen=50)
        self.on_update: list[UpdateListener] = []
        self.on_status_text: list[StatusListener] = []
        self.on_time: list[TimeListener] = []

    @property
    def latest(self) -> Telemetry:
        return self._state

    def update(self, **fields: Any) -> None:
        self.messages += 1
        self._state = replace(self._state, updated_wall=time.monotonic(), **fields)
        keys = frozenset(fields)
        for listener in self.on_update:
            listener(keys, self._state)

    def status_text(self, severity: str, text: str) -> StatusText:
        """Record one STATUSTEXT (also counts as a sign of life) and tell the listeners."""
        st = StatusText(time.monotonic(), severity, text)
        self.statustexts.append(st)
        self.update()
        for listener in self.on_status_text:
            listener(st)
        return st

    def time_sample(self, vehicle_unix_s: float, mono_s: float | None = None) -> None:
        """One SYSTEM_TIME sample: tell the listeners with its arrival time (now, unless the
        receiver stamped it earlier)."""
        mono = time.monotonic() if mono_s is None else mono_s
        for listener in self.on_time:
            listener(vehicle_unix_s, mono)

    def recent_status_text(self, within_s: float = 10.0) -> list[StatusText]:
        """STATUSTEXTs that arrived in the last `within_s` wall seconds, oldest first."""
        now = time.monotonic()
        return [st for st in self.statustexts if now - st.mono_s <= within_s]

    def age_s(self) -> float:
        """Wall seconds since the last telemetry message (inf before the first)."""
        return math.inf if self._state.updated_wall == 0.0 else (
            time.monotonic() - self._state.updated_wall)


class Vehicle(Protocol):
    """The vehicle port: what the mission needs from any autopilot."""

    hub: TelemetryHub

    async def connect(self, url: str, timeout_s: float) -> None: ...
    async def run_telemetry(self) -> None: ...
    async def wait_ready(self, timeout_s: float) -> None: ...
    async def upload_geofence(self, polygon_latlon_deg: list[tuple[float, float]]) -> bool: ...
    async def read_params(self, specs: Sequence[tuple[str, str]]) -> dict[str, float | None]: ...
    async def download_geofence(self) -> list[list[tuple[float, float]]]: ...
    async def arm(self) -> None: ...
    async def takeoff(self, alt_m: float) -> None: ...
    async def start_offboard(self, yaw_deg: float) -> None: ...
    async def set_velocity_ned(self, v_north_m_s: float, v_east_m_s: float, v_down_m_s: float,
                               yaw_deg: float) -> None: ...
    async def hold(self) -> None: ...
    async def return_to_launch(self) -> None: ...
    async def land(self) -> None: ...
    async def close(self) -> None: ...


async def wait_until(
    predicate: Callable[[], bool], timeout_s: float, what: str, poll_s: float = 0.05
) -> None:
    """Poll `predicate` until true, or raise VehicleError(what, 'timeout') after timeout_s."""
    try:
        async with asyncio.timeout(timeout_s):
            while not predicate():
                await asyncio.sleep(poll_s)
    except TimeoutError:
        raise VehicleError(what, f"timeout after {timeout_s:.0f} s") from None


_mavsdk_log_routed = False


def route_mavsdk_log() -> None:
    """Send MAVSDK's native log lines to the `mavsdk` Python logger instead of stdout, where
    they would scribble over the terminal UI and the progress lines. Once per process."""
    global _mavsdk_log_routed
    if _mavsdk_log_routed:
        return
    from mavsdk.logging import LogLevel, log_subscribe

    mav_log = logging.getLogger("mavsdk")
    levels = {LogLevel.DEBUG: logging.DEBUG, LogLevel.INFO: logging.INFO,
              LogLevel.WARN: logging.WARNING, LogLevel.ERROR: logging.ERROR}

    def handler(level: LogLevel, message: str, _file: str | None, _line: int) -> bool:
        mav_log.log(levels.get(level, logging.INFO), "%s", message)
        return True

    log_subscribe(handler)
    _mavsdk_log_routed = True


def mavsdk_reason(exc: BaseException) -> str:
    """The reason of a failed MAVSDK call: its plugin error's public ``result`` (an enum such as
    ``ActionResult.COMMAND_DENIED``) by name, else the exception's text."""
    result = getattr(exc, "result", None)
    name = getattr(result, "name", None)
    return str(name) if name else str(exc)


async def _to_the_end(name: str, pump: Coroutine[Any, Any, None]) -> None:
    """Run a telemetry pump, which only ends when its stream does: that is an error."""
    await pump
    raise VehicleError(f"telemetry stream {name}", "ended")


class MavsdkVehicle:
    """`Vehicle` through MAVSDK's native asyncio binding. Plugins live as long as this object."""

    COMMAND_TIMEOUT_S = 10.0

    def __init__(self, tlog_path: Path | None = None) -> None:
        """`tlog_path`: write the MAVLink link there (io.mavlink_tap; UDP URLs only)."""
        self.hub = TelemetryHub()
        self.tlog_path = tlog_path
        self.tap: MavlinkTap | None = None
        self._mavsdk: Any = None
        self._system: Any = None
        self._plugins: dict[str, Any] = {}

    # -- life --------------------------------------------------------------------------------

    async def connect(self, url: str, timeout_s: float = 30.0) -> None:
        from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
        from mavsdk.asyncio.plugins.action import ActionAsync
        from mavsdk.asyncio.plugins.geofence import GeofenceAsync
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
        from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync
        from mavsdk.asyncio.plugins.offboard import OffboardAsync
        from mavsdk.asyncio.plugins.param import ParamAsync
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        route_mavsdk_log()
        if self.tlog_path is not None and self.tap is None:
            if tappable(url):
                try:
                    self.tap = MavlinkTap(url, self.tlog_path)
                except (OSError, ValueError) as exc:
                    raise VehicleError(f"tap({url})", str(exc)) from exc
            else:
                log.warning("%s: not a UDP URL; no %s is written", url, self.tlog_path.name)
        if self.tap is not None:
            url = self.tap.gcs_url
        config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
        self._mavsdk = Mavsdk(config)
        try:
            await self._mavsdk.add_any_connection(url)
        except Exception as exc:
            raise VehicleError(f"add_any_connection({url})", str(exc)) from exc
        system = await self._mavsdk.first_autopilot(timeout_s=timeout_s)
        if system is None:
            raise VehicleError(f"connect({url})", f"no autopilot heard within {timeout_s:.0f} s")
        self._system = system
        self._plugins = {
            "telemetry": TelemetryAsync(system),
            "action": ActionAsync(system),
            "offboard": OffboardAsync(system),
            "geofence": GeofenceAsync(system),
            "mavlink_direct": MavlinkDirectAsync(system),
            "param": ParamAsync(system),
            "mission_raw": MissionRawAsync(system),
        }
        self.hub.update(connected=True)

    async def close(self) -> None:
        self._plugins.clear()
        if self._mavsdk is not None:
            with contextlib.suppress(Exception):
                self._mavsdk.destroy()
            self._mavsdk = None
        if self.tap is not None:
            await asyncio.to_thread(self.tap.close)
            self.tap = None

    # -- telemetry ---------------------------------------------------------------------------

    async def run_telemetry(self) -> None:
        """Consume every stream until cancelled: one task per MAVSDK subscription. A stream
        that ends (MAVSDK closed it) raises VehicleError naming it: the others would keep the
        link looking fresh while, say, the flight mode is no longer watched."""
        tel = self._plugins["telemetry"]
        streams: list[tuple[Callable[[], AsyncIterator[Any]], Callable[[Any], dict[str, Any]]]]
        streams = [
            (tel.subscribe_position, lambda p: {
                "lat_deg": p.latitude_deg, "lon_deg": p.longitude_deg,
                "abs_alt_m": p.absolute_altitude_m, "rel_alt_m": p.relative_altitude_m}),
            (tel.subscribe_velocity_ned, lambda v: {
                "v_north_m_s": v.north_m_s, "v_east_m_s": v.east_m_s, "v_down_m_s": v.down_m_s}),
            (tel.subscribe_heading, lambda h: {"yaw_deg": h.heading_deg % 360.0}),
            (tel.subscribe_armed, lambda a: {"armed": bool(a)}),
            (tel.subscribe_in_air, lambda a: {"in_air": bool(a)}),
            (tel.subscribe_landed_state, lambda s: {"landed_state": s.name}),
            (tel.subscribe_flight_mode, lambda m: {"flight_mode": m.name}),
            (tel.subscribe_battery, lambda b: {"battery_percent": _percent(b.remaining_percent)}),
            (tel.subscribe_health, lambda h: {
                "global_position_ok": h.is_global_position_ok,
                "home_position_ok": h.is_home_position_ok, "armable": h.is_armable}),
            (tel.subscribe_home, lambda h: {
                "home_lat_deg": h.latitude_deg, "home_lon_deg": h.longitude_deg,
                "home_abs_alt_m": h.absolute_altitude_m}),
        ]
        try:
            async with asyncio.TaskGroup() as tg:
                for subscribe, convert in streams:
                    name = getattr(subscribe, "__name__", "stream").removeprefix("subscribe_")
                    tg.create_task(_to_the_end(name, self._pump(subscribe, convert)))
                tg.create_task(_to_the_end("connection", self._pump_connection()))
                tg.create_task(_to_the_end("status_text", self._pump_status_text(tel)))
                tg.create_task(_to_the_end("time", self._pump_time(tel)))
        except* VehicleError as group:
            raise group.exceptions[0] from None

    async def _pump(self, subscribe: Callable[[], AsyncIterator[Any]],
                    convert: Callable[[Any], dict[str, Any]]) -> None:
        async for msg in subscribe():
            try:
                self.hub.update(**convert(msg))
            except (AttributeError, TypeError, ValueError) as exc:  # a malformed value
                log.warning("telemetry value ignored: %s", exc)

    async def _pump_status_text(self, tel: Any) -> None:
        async for st in tel.subscribe_status_text():
            severity = getattr(getattr(st, "type", None), "name", "info").lower()
            # PX4 pads some texts with a tab: the log keeps the words
            self.hub.status_text(severity, str(getattr(st, "text", "")).rstrip())

    async def _pump_time(self, tel: Any) -> None:
        """The vehicle's clock: both SYSTEM_TIME fields through MAVSDK's MAVLink-direct plugin
        (``boot_unix + time_boot_ms``, io.clock.BootAnchor); the unix field alone if that
        plugin is missing."""
        direct = self._plugins.get("mavlink_direct")
        if direct is not None:
            await self._pump_system_time(direct)
            return
        await self._pump_unix_time(tel)

    async def _pump_system_time(self, direct: Any) -> None:
        """SYSTEM_TIME (PX4 sends it at 1 Hz) as raw MAVLink, both fields, stamped when the
        event loop takes it (a late stamp only delays: the clock fit keeps the earliest)."""
        anchor = BootAnchor()
        async for msg in direct.subscribe_message("SYSTEM_TIME"):
            mono = time.monotonic()
            try:
                fields = json.loads(msg.fields_json)
                unix_s = float(fields["time_unix_usec"]) / 1e6
                boot_s = float(fields["time_boot_ms"]) / 1e3
            except (KeyError, TypeError, ValueError) as exc:  # a malformed message
                log.warning("SYSTEM_TIME ignored: %s", exc)
                continue
            for vehicle_s, arrival in anchor.add(unix_s, boot_s, mono):
                self.hub.time_sample(vehicle_s, arrival)

    async def _pump_unix_time(self, tel: Any) -> None:
        """SYSTEM_TIME (PX4 sends it at 1 Hz on the onboard link) in microseconds, stamped on
        arrival in MAVSDK's own thread (so a busy event loop does not delay the stamp); the
        public async stream, stamped in the loop, if the native plugin is not reachable."""
        native = getattr(tel, "_plugin", None)
        if native is None or not hasattr(native, "subscribe_unix_epoch_time"):
            async for time_us in tel.subscribe_unix_epoch_time():
                self.hub.time_sample(float(time_us) / 1e6)
            return
        loop = asyncio.get_running_loop()
        queue: asyncio.Queue[tuple[float, float]] = asyncio.Queue(maxsize=64)

        def put(item: tuple[float, float]) -> None:
            if not queue.full():
                queue.put_nowait(item)

        def callback(time_us: Any, _user_data: Any) -> None:  # MAVSDK's thread
            loop.call_soon_threadsafe(put, (float(time_us) / 1e6, time.monotonic()))

        handle = native.subscribe_unix_epoch_time(callback)
        try:
            while True:
                unix_s, mono_s = await queue.get()
                self.hub.time_sample(unix_s, mono_s)
        finally:
            with contextlib.suppress(Exception):
                native.unsubscribe_unix_epoch_time(handle)

    async def _pump_connection(self) -> None:
        async for connected in self._system.is_connected_state():
            self.hub.update(connected=bool(connected))
            log.warning("vehicle link %s", "regained" if connected else "lost")

    async def wait_ready(self, timeout_s: float = 30.0) -> None:
        """Global position and home known (PX4 health flags)."""
        def ready() -> bool:
            t = self.hub.latest
            return t.global_position_ok and t.home_position_ok and t.has_position and t.has_home
        await wait_until(ready, timeout_s, "wait for health (global position, home)")

    # -- commands ----------------------------------------------------------------------------

    async def _call(self, what: str, coro: Awaitable[Any]) -> Any:
        try:
            async with asyncio.timeout(self.COMMAND_TIMEOUT_S):
                return await coro
        except TimeoutError:
            raise VehicleError(what, f"no answer within {self.COMMAND_TIMEOUT_S:.0f} s") from None
        except VehicleError:
            raise
        except Exception as exc:  # MAVSDK's ActionError, OffboardError, ...
            raise VehicleError(what, mavsdk_reason(exc)) from exc

    async def upload_geofence(self, polygon_latlon_deg: list[tuple[float, float]]) -> bool:
        from mavsdk.asyncio.plugins.geofence import FenceType, GeofenceData, Point, Polygon

        poly = Polygon([Point(lat, lon) for lat, lon in polygon_latlon_deg], FenceType.INCLUSION)
        await self._call("upload_geofence",
                         self._plugins["geofence"].upload_geofence(GeofenceData([poly], [])))
        return True

    async def read_params(self, specs: Sequence[tuple[str, str]]) -> dict[str, float | None]:
        """Each (name, "int" | "float") through MAVSDK's param plugin, in PX4's declared type
        first and the other if the vehicle says WRONG_TYPE; None for a parameter the vehicle
        does not answer (another firmware version)."""
        param = self._plugins["param"]
        out: dict[str, float | None] = {}
        for name, kind in specs:
            getters = ((param.get_param_int, param.get_param_float) if kind == "int"
                       else (param.get_param_float, param.get_param_int))
            out[name] = None
            for getter in getters:
                try:
                    out[name] = float(await self._call(f"get_param({name})", getter(name)))
                    break
                except VehicleError as exc:
                    if "WRONG_TYPE" not in exc.result:
                        log.warning("parameter %s not read: %s", name, exc.result)
                        break
        return out

    async def download_geofence(self) -> list[list[tuple[float, float]]]:
        """The polygons of the fence on the vehicle (MAVLink mission protocol, type FENCE),
        each as [(lat_deg, lon_deg)]; circles are returned as their centre only. [] when no
        fence is on board."""
        items = await self._call("download_geofence",
                                 self._plugins["mission_raw"].download_geofence())
        polygons: list[list[tuple[float, float]]] = []
        current: list[tuple[float, float]] = []
        for it in items:
            lat, lon = it.x / 1e7, it.y / 1e7
            if it.command in (5001, 5002):  # polygon vertex, inclusion / exclusion
                current.append((lat, lon))
                if len(current) >= max(int(it.param1), 1):
                    polygons.append(current)
                    current = []
            elif it.command in (5003, 5004):  # circle
                polygons.append([(lat, lon)])
        if current:
            polygons.append(current)
        return polygons

    async def arm(self) -> None:
        await self._call("arm", self._plugins["action"].arm())

    async def takeoff(self, alt_m: float) -> None:
        action = self._plugins["action"]
        await self._call("set_takeoff_altitude", action.set_takeoff_altitude(float(alt_m)))
        await self._call("takeoff", action.takeoff())

    async def start_offboard(self, yaw_deg: float) -> None:
        from mavsdk.asyncio.plugins.offboard import VelocityNedYaw

        offboard = self._plugins["offboard"]
        await self._call("offboard.set_velocity_ned",
                         offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, 0.0, yaw_deg)))
        await self._call("offboard.start", offboard.start())

    async def set_velocity_ned(self, v_north_m_s: float, v_east_m_s: float, v_down_m_s: float,
                               yaw_deg: float) -> None:
        from mavsdk.asyncio.plugins.offboard import VelocityNedYaw

        await self._call("offboard.set_velocity_ned", self._plugins["offboard"].set_velocity_ned(
            VelocityNedYaw(v_north_m_s, v_east_m_s, v_down_m_s, yaw_deg)))

    async def stop_offboard(self) -> None:
        await self._call("offboard.stop", self._plugins["offboard"].stop())

    async def hold(self) -> None:
        await self._call("hold", self._plugins["action"].hold())

    async def return_to_launch(self) -> None:
        await self._call("return_to_launch", self._plugins["action"].return_to_launch())

    async def land(self) -> None:
        await self._call("land", self._plugins["action"].land())

    async def disarm(self) -> None:
        await self._call("disarm", self._plugins["action"].disarm())


def _percent(remaining: float) -> float:
    """MAVSDK >= 2 reports battery remaining in percent (0-100); NaN when unknown."""
    return float(remaining) if math.isfinite(remaining) else math.nan
