"""VehicleClock: the mission's time base fitted to the vehicle's SYSTEM_TIME samples."""

from __future__ import annotations

import asyncio
import time

import numpy as np
import pytest

from mexgen_gcs.io.clock import VehicleClock, WallClock


class FakeMonotonic:
    def __init__(self, t: float = 1000.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def _feed(clock: VehicleClock, mono: FakeMonotonic, rate: float, n: int, *, hz: float = 1.0,
          jitter_s: float = 0.0, v0: float = 1.7e9, seed: int = 0) -> None:
    rng = np.random.default_rng(seed)
    start = mono.t
    for i in range(n):
        mono.t = start + i / hz
        delay = abs(rng.normal(0.0, jitter_s)) if jitter_s else 0.0  # arrival is late
        clock.observe(v0 + rate * (mono.t - start), mono.t + delay)


def test_px4_rate_is_measured_not_assumed():
    """PX4 SITL at speed factor 4 runs about 0.96 * 4: the fit recovers that rate."""
    mono = FakeMonotonic()
    clock = VehicleClock(monotonic=mono)
    _feed(clock, mono, 0.96 * 4, 30)
    assert clock.synced and clock.source == "vehicle"
    assert clock.rate == pytest.approx(3.84, rel=1e-9)
    v_now = 1.7e9 + 3.84 * 29
    assert clock.now() == pytest.approx(v_now, abs=1e-6)
    mono.t += 10.0  # 10 wall seconds later: 38.4 vehicle seconds
    assert clock.now() == pytest.approx(v_now + 38.4, abs=1e-6)
    assert clock.wall_seconds(5.0) == pytest.approx(5.0 / 3.84)


def test_jittery_arrivals_still_give_the_rate():
    """Arrival stamps late by |N(0, 30 ms)|: the rate is within 0.5 % after 30 samples and
    the time within a few tenths of a vehicle second."""
    mono = FakeMonotonic()
    clock = VehicleClock(monotonic=mono)
    _feed(clock, mono, 3.84, 30, jitter_s=0.03, seed=1)
    assert clock.rate == pytest.approx(3.84, rel=5e-3)
    assert abs(clock.now() - (1.7e9 + 3.84 * 29)) < 0.3
    assert clock.residual_rms_s < 0.2


def test_fallback_is_wall_time_and_says_so():
    clock = VehicleClock()
    assert clock.source == "wall" and not clock.synced and clock.rate == 1.0
    assert abs(clock.now() - time.time()) < 0.5
    mono = FakeMonotonic()
    fixed = VehicleClock(fixed_rate=10.0, monotonic=mono)
    t0 = fixed.now()
    mono.t += 1.0
    assert fixed.now() - t0 == pytest.approx(10.0)  # the fixed rate applies before samples


def test_a_stalled_simulator_is_followed_and_a_late_sample_ignored():
    """A simulated vehicle at 20x stalls and drops 3 s of its time (its tick loop was late):
    two samples later the mission clock is back on it, at the same rate. A single sample
    that arrived late (a busy loop) does not drag the clock back."""
    mono = FakeMonotonic()
    clock = VehicleClock(monotonic=mono)
    _feed(clock, mono, 20.0, 15)
    v = 1.7e9 + 20.0 * 14
    mono.t += 1.0
    clock.observe(v + 20.0, mono.t + 0.25)  # stamped 0.25 s late: 5 vehicle seconds
    assert abs(clock.now() - (v + 20.0)) < 0.2
    v += 20.0
    for step in (20.0 - 3.0, 20.0):  # the stall drops 3 s, then it runs on
        mono.t += 1.0
        v += step
        clock.observe(v, mono.t)
    assert abs(clock.now() - v) < 0.5
    mono.t += 0.5
    assert abs(clock.now() - (v + 10.0)) < 0.6
    assert clock.rate == pytest.approx(20.0, rel=0.1)


def test_one_sample_gives_the_offset_two_close_ones_no_rate_yet():
    mono = FakeMonotonic()
    clock = VehicleClock(monotonic=mono)
    clock.observe(1.8e9, mono.t)
    assert clock.source == "syncing" and not clock.synced
    assert clock.now() == pytest.approx(1.8e9)
    mono.t += 0.1
    clock.observe(1.8e9 + 1.0, mono.t)  # rate 10 over 0.1 s: too short a span to trust
    assert not clock.synced and clock.rate == 1.0


def test_fixed_rate_fits_only_the_offset():
    mono = FakeMonotonic()
    clock = VehicleClock(fixed_rate=4.0, monotonic=mono)
    _feed(clock, mono, 3.84, 5)
    assert clock.synced and clock.rate == 4.0  # as told, even though the vehicle runs 3.84


def test_bad_samples_are_ignored_and_a_jump_restarts_the_fit():
    mono = FakeMonotonic()
    clock = VehicleClock(monotonic=mono)
    assert not clock.observe(0.0)  # SYSTEM_TIME not set yet
    assert not clock.observe(float("nan"))
    assert clock.samples_rejected == 2 and clock.source == "wall"
    _feed(clock, mono, 1.0, 10)
    assert clock.synced
    mono.t += 1.0
    clock.observe(1.7e9 + 3600.0, mono.t)  # the vehicle set its clock one hour later
    assert clock.restarts == 1 and not clock.synced
    assert clock.now() == pytest.approx(1.7e9 + 3600.0)


def test_now_never_steps_back_on_fit_noise():
    mono = FakeMonotonic()
    clock = VehicleClock(monotonic=mono)
    _feed(clock, mono, 1.0, 5)
    before = clock.now()
    clock.observe(1.7e9 + 4.0 - 0.5, mono.t + 0.01)  # a sample pulling the fit back
    assert clock.now() >= before


def test_old_samples_leave_the_window():
    mono = FakeMonotonic()
    clock = VehicleClock(monotonic=mono, window_s=20.0)
    _feed(clock, mono, 2.0, 30)
    v = 1.7e9 + 2.0 * 29
    for _ in range(30):  # the vehicle's rate changes to 3: the window forgets the old one
        mono.t += 1.0
        v += 3.0
        clock.observe(v, mono.t)
    assert clock.rate == pytest.approx(3.0, rel=1e-6)


def test_rejects_bad_fixed_rate():
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="time scale"):
            VehicleClock(fixed_rate=bad)


async def test_sleep_is_vehicle_seconds():
    mono = FakeMonotonic()
    clock = VehicleClock(fixed_rate=20.0, monotonic=mono)
    t0 = time.monotonic()
    await clock.sleep(2.0)  # 0.1 s of wall time
    # 0.1 s of wall time; on the wrong clock it would be 2 s (load only lengthens a sleep)
    assert 0.08 <= time.monotonic() - t0 < 1.0
    wall = WallClock()
    a = wall.now()
    await wall.sleep(0.05)
    assert 0.04 <= wall.now() - a < 0.5 and wall.rate == 1.0
    assert asyncio.get_running_loop() is not None


def test_boot_anchor_on_an_aircraft_is_unix_minus_boot():
    from mexgen_gcs.io.clock import BootAnchor
    anchor = BootAnchor()
    out = [anchor.add(1.7e9 + k, 300.0 + k, float(k)) for k in range(5)]
    assert out[:2] == [[], []]  # three pairs spanning 2 s are needed first
    # then the pairs held so far all at once (with their arrival times), then one per pair
    assert out[2] == [(pytest.approx(1.7e9 + k), float(k)) for k in range(3)]
    assert out[3] == [(pytest.approx(1.7e9 + 3), 3.0)]
    assert anchor.rate == pytest.approx(1.0)


def test_boot_anchor_on_px4_sitl_runs_on_the_boot_clock():
    """PX4 SITL at speed factor 4: SYSTEM_TIME's unix is the host's wall clock, time_boot_ms
    the simulated one (3.9x). Vehicle time follows the boot clock from the host time at boot,
    whenever the observer starts listening."""
    from mexgen_gcs.io.clock import BootAnchor
    boot_host = 1.7e9
    for start in (10.0, 100.0):  # two observers, one arriving later
        anchor = BootAnchor()
        got = [anchor.add(boot_host + w, 3.9 * w, w) for w in np.arange(start, start + 8.0)]
        assert anchor.rate == pytest.approx(3.9)
        assert anchor.boot_unix_s == pytest.approx(boot_host)
        assert got[-1][0][0] == pytest.approx(boot_host + 3.9 * (start + 7.0))


def test_boot_anchor_ignores_unset_time_and_restarts_on_reboot():
    from mexgen_gcs.io.clock import BootAnchor
    anchor = BootAnchor(min_samples=2, span_s=1.0)
    assert anchor.add(0.0, 5.0) == []  # no GPS time yet
    assert anchor.add(1.7e9, 6.0) == []
    assert [v for v, _ in anchor.add(1.7e9 + 1, 7.0)] == pytest.approx([1.7e9, 1.7e9 + 1])
    assert anchor.add(1.7e9 + 2, float("nan")) == []
    assert anchor.add(1.7e9 + 50, 1.0) == []  # rebooted: anchors again
    assert [v for v, _ in anchor.add(1.7e9 + 51, 2.0)] == pytest.approx([1.7e9 + 50,
                                                                          1.7e9 + 51])
