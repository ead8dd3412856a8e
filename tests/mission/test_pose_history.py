"""Pose history: detections posed at their own timestamp (interpolated, shortest-arc yaw), and
the receiver pose of a detection (datagram pose AMSL minus the vehicle's home, or history)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from mexgen_gcs.core.geo import LocalFrame
from mexgen_gcs.io.vehicle import TelemetryHub
from mexgen_gcs.io.wire import Detection
from mexgen_gcs.mission.ingest import POSE_TOLERANCE_S, receiver_pose
from mexgen_gcs.mission.pose_history import Pose, PoseHistory


def _history(yaws=(350.0, 10.0)) -> PoseHistory:
    h = PoseHistory(span_s=30.0)
    h.add(Pose(100.0, 0.0, 0.0, 50.0, yaws[0]))
    h.add(Pose(101.0, 10.0, -4.0, 52.0, yaws[1]))
    return h


def test_position_and_height_are_interpolated_linearly():
    p = _history().at(100.25, 0.5)
    assert (p.east_m, p.north_m, p.up_m) == pytest.approx((2.5, -1.0, 50.5))
    assert p.t == 100.25


@pytest.mark.parametrize(("yaws", "f", "expected"), [
    ((350.0, 10.0), 0.5, 0.0),      # across north: 0, not 180
    ((350.0, 10.0), 0.25, 355.0),
    ((10.0, 350.0), 0.75, 355.0),
    ((90.0, 260.0), 0.5, 175.0),
    ((179.0, 181.0), 0.5, 180.0),
    ((100.0, 280.0), 0.5, 10.0),    # a half turn, either way: one way, consistently
])
def test_yaw_takes_the_shortest_arc(yaws, f, expected):
    p = _history(yaws).at(100.0 + f, 0.5)
    assert math.isclose((p.yaw_deg - expected + 180.0) % 360.0 - 180.0, 0.0, abs_tol=1e-9)


def test_outside_the_history_by_more_than_the_tolerance_is_none():
    h = _history()
    assert h.at(101.3, 0.5).t == 101.0  # newer than the newest, within tolerance: the newest
    assert h.at(99.6, 0.5).t == 100.0
    assert h.at(101.6, 0.5) is None and h.at(99.0, 0.5) is None
    assert PoseHistory().at(100.0, 10.0) is None
    assert h.at(math.nan, 1.0) is None


def test_old_samples_leave_and_out_of_order_or_bad_ones_are_ignored():
    h = PoseHistory(span_s=10.0)
    for k in range(3000):
        h.add(Pose(float(k) * 0.1, float(k), 0.0, 50.0, 0.0))
    assert h.span == pytest.approx((289.9, 299.9))
    h.add(Pose(5.0, 0.0, 0.0, 0.0, 0.0))  # older than the newest
    h.add(Pose(400.0, math.nan, 0.0, 0.0, 0.0))
    assert h.span[1] == pytest.approx(299.9)
    p = h.at(295.05, 0.1)
    assert p.east_m == pytest.approx(2950.5)


def _ctx(history: PoseHistory, home_alt_amsl: float = 350.0):
    hub = TelemetryHub()
    hub.update(home_abs_alt_m=home_alt_amsl, yaw_deg=123.0)
    return SimpleNamespace(poses=history, frame=LocalFrame(-34.9, 138.6, 0.0),
                           vehicle=SimpleNamespace(hub=hub))


def test_a_detection_is_posed_at_its_own_time_not_at_arrival():
    ctx = _ctx(_history())
    det = Detection(t=100.5, tag="T1", freq_hz=None, rssi_db=-60.0)
    xyz, yaw = receiver_pose(ctx, det)
    np.testing.assert_allclose(xyz, [5.0, -2.0, 51.0])
    assert math.degrees(yaw) == pytest.approx(0.0, abs=1e-9)
    late = Detection(t=101.0 + POSE_TOLERANCE_S + 0.1, tag="T1", freq_hz=None, rssi_db=-60.0)
    assert receiver_pose(ctx, late) is None


def test_a_datagram_pose_in_amsl_is_a_height_above_the_vehicles_home():
    """A site 350 m above sea level: the receiver at 400 m AMSL is 50 m above the tags, not
    400 m (and not 400 - home.alt_m from the mission file)."""
    ctx = _ctx(_history(), home_alt_amsl=350.0)
    lat, lon, _ = ctx.frame.to_geodetic(30.0, 40.0)
    det = Detection(t=100.5, tag="T1", freq_hz=None, rssi_db=-60.0, lat=float(lat),
                    lon=float(lon), alt_m=400.0, yaw_deg=None)
    xyz, yaw = receiver_pose(ctx, det)
    np.testing.assert_allclose(xyz, [30.0, 40.0, 50.0], atol=1e-6)
    assert math.degrees(yaw) == pytest.approx(0.0, abs=1e-9)  # yaw from the history at t
    no_home = _ctx(PoseHistory(), home_alt_amsl=math.nan)
    assert receiver_pose(no_home, det) is None  # no height known: not used
