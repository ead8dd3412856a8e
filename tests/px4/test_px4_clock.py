"""PX4 SITL's clocks at speed factor K, as a GCS sees them on the offboard link (14540+i).

Measured with pymavlink: SYSTEM_TIME (time_unix_usec, time_boot_ms) over ~10 s of wall time.
``time_boot_ms`` runs a little slower than K (the lockstep loop cannot keep up exactly); the
unix field is the HOST's wall clock (PX4 SITL does not simulate CLOCK_REALTIME).
"""

from __future__ import annotations

import os
import time

import pytest

from sim.vehicle_link import fit_boot_unix
from tests.px4.conftest import Px4Factory

os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil  # reads MAVLINK20 on import

pytestmark = pytest.mark.px4

WINDOW_S = 10.0


@pytest.mark.parametrize("k", [4.0, 10.0])
def test_px4_clock_rate(px4_factory: Px4Factory, k: float) -> None:
    px4 = px4_factory(speed_factor=k)
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{px4.offboard_port}",
                                      source_system=250, source_component=191)
    try:
        samples: list[tuple[float, float, float]] = []  # host monotonic, unix, boot
        t_end = time.monotonic() + WINDOW_S
        while time.monotonic() < t_end:
            m = conn.recv_match(type="SYSTEM_TIME", blocking=True, timeout=1.0)
            if m is not None and m.get_srcSystem() == px4.sysid:
                samples.append((time.monotonic(), m.time_unix_usec / 1e6, m.time_boot_ms / 1e3))
    finally:
        conn.close()
    assert len(samples) > 10
    (w0, u0, b0), (w1, u1, b1) = samples[0], samples[-1]
    boot_rate, unix_rate = (b1 - b0) / (w1 - w0), (u1 - u0) / (w1 - w0)
    boot_unix, fitted = fit_boot_unix([(u, b) for _, u, b in samples])
    print(f"K={k:g}: time_boot_ms {boot_rate:.3f}x ({boot_rate / k:.3f} K), SYSTEM_TIME unix "
          f"{unix_rate:.4f}x, fitted rate {fitted:.3f}, boot_unix - PX4 start "
          f"{boot_unix - (time.time() - (time.monotonic() - px4.started_wall_s)):+.2f} s, "
          f"{len(samples)} samples in {w1 - w0:.1f} s")
    assert 0.7 * k < boot_rate <= 1.01 * k
    assert unix_rate == pytest.approx(1.0, abs=0.02)  # the host's clock, not the vehicle's
    assert fitted == pytest.approx(boot_rate, rel=0.02)
