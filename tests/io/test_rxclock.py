"""ReceiverClock: a receiver's clock offset and drift learnt from its heartbeats' timestamps
and their arrival on the mission clock (fake sequences: heartbeats at 1 Hz with random
non-negative delays drawn from a seeded Generator)."""

from __future__ import annotations

import numpy as np
import pytest

from mexgen_gcs.io.rxclock import ReceiverClock

M0 = 1.7e9


def heartbeats(offset_s: float, drift_ppm: float, n: int, *, delay_mean_s: float = 0.005,
               spike_every: int = 0, spike_s: float = 5.0, seed: int = 0
               ) -> list[tuple[float, float]]:
    """(receiver_t, arrival_m) pairs: sent every mission second from M0 by a clock
    ``offset_s`` off and ``drift_ppm`` fast, each arriving after a random delay (every
    ``spike_every``-th one ``spike_s`` late)."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        sent_m = M0 + i
        r = sent_m + offset_s + drift_ppm * 1e-6 * i
        delay = 0.0005 + float(rng.exponential(delay_mean_s))
        if spike_every and i % spike_every == spike_every - 1:
            delay += spike_s
        out.append((r, sent_m + delay))
    return out


def feed(clock: ReceiverClock, pairs: list[tuple[float, float]]) -> list[str | None]:
    return [clock.observe(r, m) for r, m in pairs]


@pytest.mark.parametrize(("offset_s", "drift_ppm"), [(600.0, 0.0), (0.0, 100.0),
                                                     (-3600.0, -250.0), (600.0, 100.0),
                                                     (-1.0, -7000.0)])
def test_learns_offset_and_drift(offset_s: float, drift_ppm: float) -> None:
    clock = ReceiverClock()
    changes = feed(clock, heartbeats(offset_s, drift_ppm, 300))
    assert changes[0] == "first" and changes[1:].count("first") == 0
    assert "jump" not in changes
    true_now = offset_s + drift_ppm * 1e-6 * 299
    # the offset reads low by about the mean least delay per 2 s bucket (~3 ms here)
    assert true_now - 0.02 < clock.offset_s < true_now + 0.002
    assert abs(clock.drift_ppm - drift_ppm) < 30.0
    # a pulse heard at mission time M0 + 250 is put back there
    r = M0 + 250 + offset_s + drift_ppm * 1e-6 * 250
    assert abs(clock.to_mission(r) - (M0 + 250)) < 0.02


def test_drift_is_zero_until_the_window_spans_20_s_then_measured() -> None:
    clock = ReceiverClock()
    pairs = heartbeats(0.0, 5000.0, 60)
    feed(clock, pairs[:15])
    assert clock.drift_ppm == 0.0 and clock.ready
    feed(clock, pairs[15:])
    assert abs(clock.drift_ppm - 5000.0) < 300.0


def test_late_datagrams_do_not_drag_the_offset_or_make_a_jump() -> None:
    clock = ReceiverClock()
    changes = feed(clock, heartbeats(600.0, 0.0, 200, spike_every=7, spike_s=8.0))
    assert "jump" not in changes
    assert abs(clock.offset_s - 600.0) < 0.02
    assert clock.samples_held_back > 0


def test_a_step_of_the_clock_is_a_jump_and_is_followed() -> None:
    clock = ReceiverClock()
    before = heartbeats(600.0, 0.0, 100)
    after = [(r - 600.0 + 45.0 + 100.0, m + 100.0) for r, m in heartbeats(600.0, 0.0, 100, seed=1)]
    changes = feed(clock, before + after)
    assert changes.count("jump") == 1 and clock.jumps == 1
    assert changes.index("jump") == 100 + 2  # confirmed by the third sample off the fit
    assert abs(clock.offset_s - 45.0) < 0.02


def test_spikes_both_ways_are_not_a_jump() -> None:
    clock = ReceiverClock()
    feed(clock, heartbeats(10.0, 0.0, 50))
    m = M0 + 50
    changes = [clock.observe(m + 10.0 + 8.0, m), clock.observe(m + 1 + 10.0 - 8.0, m + 1),
               clock.observe(m + 2 + 10.0 + 8.0, m + 2)]
    assert changes == [None, None, None] and clock.jumps == 0
    assert abs(clock.offset_s - 10.0) < 0.02


def test_before_any_sample_times_are_used_as_sent_and_nonfinite_is_ignored() -> None:
    clock = ReceiverClock()
    assert not clock.ready and clock.to_mission(123.0) == 123.0
    assert clock.observe(float("nan"), M0) is None and not clock.ready
    assert clock.observe(M0 + 5.0, float("inf")) is None and not clock.ready
    assert clock.observe(M0 + 5.0, M0) == "first"
    assert clock.to_mission(M0 + 5.0) == pytest.approx(M0)


def test_an_absurd_drift_keeps_the_last_sane_one() -> None:
    clock = ReceiverClock(max_drift_ppm=10_000.0, jump_s=1e9)
    feed(clock, heartbeats(0.0, 200_000.0, 40))  # a clock 20 % fast is not a crystal's
    assert clock.drift_ppm == 0.0
    clock = ReceiverClock(max_drift_ppm=10_000.0, jump_s=1e9)
    feed(clock, heartbeats(0.0, 5_000.0, 40))
    assert abs(clock.drift_ppm - 5_000.0) < 300.0
