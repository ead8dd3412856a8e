"""The MAVLink mission protocol, server side, for geofences (MAV_MISSION_TYPE_FENCE).

Upload: MISSION_COUNT -> MISSION_REQUEST_INT(seq) ... <- MISSION_ITEM_INT(seq) -> MISSION_ACK.
Download: MISSION_REQUEST_LIST -> MISSION_COUNT, then MISSION_REQUEST_INT -> MISSION_ITEM_INT.
MISSION_CLEAR_ALL clears. Missions and rally points are refused honestly (MAV_MISSION_UNSUPPORTED
for uploads; downloads report zero items), because this vehicle only flies offboard.
Retries: a request not answered within ``retry_s`` (wall) is repeated up to ``max_retries``
times, then the upload is cancelled with MAV_MISSION_OPERATION_CANCELLED.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from sim.fence import Fence, FenceItem, build_fence

FENCE = mavlink.MAV_MISSION_TYPE_FENCE
MAX_ITEMS = 512
_GLOBAL_FRAMES = {0, 3, 5, 6, 10, 11}


@dataclass
class _Upload:
    system: int
    component: int
    count: int
    items: list[FenceItem]
    last_wall_s: float
    retries: int = 0


class FenceProtocol:
    """Holds the uploaded fence and answers the mission-protocol messages for it.

    ``send(msg)`` transmits a pymavlink message; ``to_enu(lat, lon) -> (east, north)`` maps
    the vertices; ``on_fence(fence)`` is called after each accepted upload or clear.
    """

    def __init__(
        self,
        mav: mavlink.MAVLink,
        send: Callable[[Any], None],
        to_enu: Callable[[float, float], tuple[float, float]],
        on_fence: Callable[[Fence], None],
        retry_s: float = 1.0,
        max_retries: int = 5,
    ) -> None:
        self._mav = mav
        self._send = send
        self._to_enu = to_enu
        self._on_fence = on_fence
        self._retry_s = retry_s
        self._max_retries = max_retries
        self.fence = Fence()
        self._upload: _Upload | None = None

    def _ack(self, system: int, component: int, result: int, mission_type: int) -> None:
        self._send(self._mav.mission_ack_encode(system, component, result, mission_type))

    def _request(self, up: _Upload, now_wall_s: float) -> None:
        seq = len(up.items)
        up.last_wall_s = now_wall_s
        self._send(self._mav.mission_request_int_encode(up.system, up.component, seq, FENCE))

    def handle(self, msg: Any, now_wall_s: float) -> bool:
        """Process a mission-protocol message; returns False if it is not one."""
        kind = msg.get_type()
        src_sys, src_comp = msg.get_srcSystem(), msg.get_srcComponent()
        mission_type = getattr(msg, "mission_type", 0)
        if kind == "MISSION_COUNT":
            self._on_count(msg, src_sys, src_comp, mission_type, now_wall_s)
        elif kind in ("MISSION_ITEM_INT", "MISSION_ITEM"):
            self._on_item(msg, kind, src_sys, src_comp, mission_type, now_wall_s)
        elif kind == "MISSION_CLEAR_ALL":
            if mission_type in (FENCE, mavlink.MAV_MISSION_TYPE_ALL):
                self._set_fence(Fence())
            self._ack(src_sys, src_comp, mavlink.MAV_MISSION_ACCEPTED, mission_type)
        elif kind == "MISSION_REQUEST_LIST":
            count = len(self.fence.items) if mission_type == FENCE else 0
            self._send(self._mav.mission_count_encode(src_sys, src_comp, count, mission_type))
        elif kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            self._on_request(msg, src_sys, src_comp, mission_type)
        elif kind == "MISSION_ACK":
            pass  # the end of a download; nothing to do
        else:
            return False
        return True

    def _on_count(self, msg: Any, src_sys: int, src_comp: int, mission_type: int,
                  now_wall_s: float) -> None:
        if mission_type != FENCE:
            self._ack(src_sys, src_comp, mavlink.MAV_MISSION_UNSUPPORTED, mission_type)
            return
        if msg.count > MAX_ITEMS:
            self._ack(src_sys, src_comp, mavlink.MAV_MISSION_NO_SPACE, mission_type)
            return
        if msg.count == 0:
            self._upload = None
            self._set_fence(Fence())
            self._ack(src_sys, src_comp, mavlink.MAV_MISSION_ACCEPTED, mission_type)
            return
        self._upload = _Upload(src_sys, src_comp, msg.count, [], now_wall_s)
        self._request(self._upload, now_wall_s)

    def _on_item(self, msg: Any, kind: str, src_sys: int, src_comp: int, mission_type: int,
                 now_wall_s: float) -> None:
        up = self._upload
        if mission_type != FENCE or up is None:
            return  # not in an upload: PX4 ignores stray items too
        if msg.seq != len(up.items):
            if msg.seq > len(up.items):
                self._request(up, now_wall_s)  # ask again for the one we need
            return
        scale = 1e7 if kind == "MISSION_ITEM_INT" and msg.frame in _GLOBAL_FRAMES else 1.0
        item = FenceItem(int(msg.command), int(msg.frame), float(msg.param1),
                         float(msg.x) / scale, float(msg.y) / scale, float(msg.z))
        if not (math.isfinite(item.lat_deg) and math.isfinite(item.lon_deg)
                and -90.0 <= item.lat_deg <= 90.0 and -180.0 <= item.lon_deg <= 180.0):
            self._upload = None
            self._ack(src_sys, src_comp, mavlink.MAV_MISSION_INVALID_PARAM5, mission_type)
            return
        up.items.append(item)
        up.retries = 0
        if len(up.items) < up.count:
            self._request(up, now_wall_s)
            return
        self._upload = None
        try:
            fence = build_fence(up.items, self._to_enu)
        except ValueError:
            self._ack(src_sys, src_comp, mavlink.MAV_MISSION_INVALID, mission_type)
            return
        self._set_fence(fence)
        self._ack(src_sys, src_comp, mavlink.MAV_MISSION_ACCEPTED, mission_type)

    def _on_request(self, msg: Any, src_sys: int, src_comp: int, mission_type: int) -> None:
        items = self.fence.items if mission_type == FENCE else ()
        if not 0 <= msg.seq < len(items):
            self._ack(src_sys, src_comp, mavlink.MAV_MISSION_INVALID_SEQUENCE, mission_type)
            return
        it = items[msg.seq]
        self._send(self._mav.mission_item_int_encode(
            src_sys, src_comp, msg.seq, it.frame, it.command, 0, 1, it.param1, 0.0, 0.0, 0.0,
            round(it.lat_deg * 1e7), round(it.lon_deg * 1e7), it.alt_m, FENCE))

    def _set_fence(self, fence: Fence) -> None:
        self.fence = fence
        self._on_fence(fence)

    def tick(self, now_wall_s: float) -> None:
        """Repeat an unanswered request, or give the upload up."""
        up = self._upload
        if up is None or now_wall_s - up.last_wall_s < self._retry_s:
            return
        if up.retries >= self._max_retries:
            self._upload = None
            self._ack(up.system, up.component, mavlink.MAV_MISSION_OPERATION_CANCELLED, FENCE)
            return
        up.retries += 1
        self._request(up, now_wall_s)
