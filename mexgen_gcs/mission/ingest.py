"""Radio ingest: every accepted datagram is logged, and each detection is posed at its OWN
timestamp and handed to the decision core.

Times: a datagram's ``t`` arrives already on the mission clock (the receiver's clock offset and
drift learnt and applied by io.radio_udp); ``t_pulse_rx`` keeps the time as the receiver sent
it, and each ``ClockReport`` becomes a ``receiver_clock`` record.

Pose of a detection: the receiver pose the datagram carries (lat/lon horizontally about the
mission home; ``alt_m`` is AMSL, so the height above the tags is ``alt_m`` minus the vehicle's
home altitude from HOME_POSITION), else the vehicle's pose at the detection's ``t`` from the
pose history (interpolated). A ``t`` outside the history by more than
``POSE_TOLERANCE_S`` vehicle seconds is counted and the pulse is not used (an event at most
every ``UNPOSED_EVENT_EVERY_S``). Frames: ENU metres about the mission home, height above the
vehicle's home, yaw in radians for the core.
"""

from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np

from mexgen_gcs.io.rxclock import ClockReport
from mexgen_gcs.io.wire import Heartbeat
from mexgen_gcs.mission.context import MissionContext

POSE_TOLERANCE_S = 1.0
"""A detection may be this much newer (or older) than the pose history and still be posed."""
UNPOSED_EVENT_EVERY_S = 10.0


async def radio_ingest(ctx: MissionContext) -> None:
    queue = ctx.receiver.queue
    last_unposed_event = -math.inf
    while True:
        item = await queue.get()
        tag_id, msg, t_rx = item.tag_id, item.event, item.t_rx_s
        now = ctx.clock.now()
        if isinstance(msg, ClockReport):
            log_receiver_clock(ctx, now, msg)
            continue
        ctx.last_radio_t = now
        if isinstance(msg, Heartbeat):
            ctx.last_heartbeat_t = now
            ctx.heartbeat_listening = (tuple(x for x in msg.listening if x in ctx.det_times)
                                       if msg.listening is not None else None)
            ctx.log.write("radio", t=now, kind="heartbeat", listening=msg.listening)
            continue
        pose = receiver_pose(ctx, msg)
        if pose is None:
            n = ctx.count("detections_unposed")
            ctx.log.write("detection", t=now, tag=tag_id, rssi_db=msg.rssi_db, t_pulse=msg.t,
                          t_pulse_rx=t_rx, freq_hz=msg.freq_hz, used=False,
                          why="no pose at t_pulse")
            if ctx.t_airborne is not None and now - last_unposed_event >= UNPOSED_EVENT_EVERY_S:
                last_unposed_event = now
                span = ctx.poses.span
                ctx.event("detection_unposed", level=logging.WARNING, tag=tag_id,
                          t_pulse=round(msg.t, 2), total=n,
                          history=None if span is None else [round(span[0], 2),
                                                             round(span[1], 2)])
            continue
        xyz, yaw_rad = pose
        ctx.log.write("detection", t=now, tag=tag_id, rssi_db=msg.rssi_db, t_pulse=msg.t,
                      t_pulse_rx=t_rx, freq_hz=msg.freq_hz, rx_en_m=xyz,
                      rx_yaw_deg=math.degrees(yaw_rad))
        try:
            ctx.core.add_detection(tag_id, msg.rssi_db, xyz, yaw_rad)
            ctx.det_times[tag_id].append(now)
        except (KeyError, ValueError) as exc:  # a tag the core lacks, a non-finite pose
            ctx.event("detection_unused", level=logging.WARNING, tag=tag_id, error=str(exc))


def log_receiver_clock(ctx: MissionContext, now: float, report: ClockReport) -> None:
    """A ``receiver_clock`` record; an event for a source's first estimate and a warning
    event when its clock jumps."""
    correcting = bool(getattr(ctx.receiver.policy, "clock_correction", True))
    ctx.log.write("receiver_clock", t=now, source=report.source, kind=report.kind,
                  offset_s=report.offset_s, drift_ppm=report.drift_ppm,
                  samples=report.samples, spread_s=report.spread_s,
                  previous_offset_s=report.previous_offset_s, correcting=correcting)
    if report.kind == "first":
        ctx.event("receiver_clock", source=report.source, offset_s=round(report.offset_s, 3),
                  correcting=correcting)
    elif report.kind == "jump":
        ctx.event("receiver_clock_jump", level=logging.WARNING, source=report.source,
                  offset_s=round(report.offset_s, 3),
                  previous_offset_s=round(report.previous_offset_s or 0.0, 3))


def receiver_pose(ctx: MissionContext, det: Any) -> tuple[np.ndarray, float] | None:
    """(ENU xyz with height above the vehicle's home, yaw radians) of the receiver at the
    detection's own time, or None when it cannot be known."""
    hist = ctx.poses.at(det.t, POSE_TOLERANCE_S)
    if det.lat is not None and det.lon is not None and det.alt_m is not None:
        e, n, _ = ctx.frame.to_enu(det.lat, det.lon)
        home_amsl = ctx.vehicle.hub.latest.home_abs_alt_m
        if math.isfinite(home_amsl):
            up = float(det.alt_m) - home_amsl
        elif hist is not None:
            up = hist.up_m
        else:
            return None
        if det.yaw_deg is not None:
            yaw_deg = float(det.yaw_deg)
        elif hist is not None:
            yaw_deg = hist.yaw_deg
        else:
            yaw_deg = ctx.vehicle.hub.latest.yaw_deg
        return np.array([float(e), float(n), up]), math.radians(yaw_deg)
    if hist is None:
        return None
    return np.array([hist.east_m, hist.north_m, hist.up_m]), math.radians(hist.yaw_deg)
