"""The simulator's radio as IQ samples, served as an rtl_tcp server (``--iq-server``).

Frame: none here (powers in dBm at the receiver; frequencies in Hz).

The same pulses as the datagram radio (`sim.radios`: each tag's schedule, the received power
at the vehicle's pose from the one radio model or drawn world) become rectangular pulses of
``receiver.pulse_width_s`` in an 8-bit IQ stream, with per-pulse fading (the model's
``noise_std_db``, log-normal), thermal noise, each tag's carrier offset and slow drift, and an
optional CW interferer; the receiver (`mexgen_gcs.receiver`) must find them. The stream's
sample ``n`` is sim time ``t0 + n / rate`` (``t0``: when the client connected or set the rate),
so at ``--speedup K`` the server sends K times the sample rate per wall second.

The dongle: ``dBFS = dBm + gain_db - CAL_OFFSET_DB``, gain as the client sets it (rtl_tcp
command 0x04, tenths of dB); a receiver calibrated with ``--cal-offset CAL_OFFSET_DB`` reports
dBm. Noise: ``NOISE_BELOW_SENSITIVITY_DB`` below the mission's ``radio.sensitivity_db`` per
hertz, where the receiver's default detector (3 kHz channels, 20 ms pulses, 1e-3 false alarms
per tag-second) hears half the pulses (A^2/N0 = 33.5 dB-Hz, from the detector's theory), so
the IQ world's sensitivity is the mission model's.

Noise is drawn once (``NOISE_BUFFER_SAMPLES``, quantised to 8 bits) and read from random
offsets, so a fast stream costs copies, not random draws; only the pulses (and a CW tone) are
computed per block. A client that does not keep up loses whole blocks, as with librtlsdr's
rtl_tcp (which drops buffers when its queue is full); the receiver detects the gap.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import struct
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from mexgen_gcs.receiver import rtltcp, synth

CAL_OFFSET_DB = synth.SIM_CAL_OFFSET_DB
NOISE_BELOW_SENSITIVITY_DB = 33.5
NOISE_BUFFER_SAMPLES = 1 << 21
DEFAULT_RATE_HZ = 2_048_000.0
MAX_QUEUE_S = 8.0  # of samples waiting in the socket before blocks are dropped


@dataclass(frozen=True, slots=True)
class IqOptions:
    host: str = "127.0.0.1"
    port: int = 0
    cw_offset_hz: float | None = None
    """CW interferer at this offset from the first tag's frequency, Hz (None = none)."""
    cw_dbm: float = -70.0
    drift_hz: float = 300.0
    """Amplitude of each tag's slow carrier drift (period 120-300 s), Hz."""
    offset_std_hz: float = 300.0
    """Standard deviation of each tag's fixed carrier offset, Hz."""


class IqRadio:
    """Renders the stream up to a sim time; pulses are queued by the radio as they happen."""

    def __init__(self, freqs_hz: list[float], pulse_width_s: float, sensitivity_db: float,
                 fading_std_db: float, options: IqOptions, rng: np.random.Generator) -> None:
        self.freqs = np.asarray(freqs_hz, dtype=float)
        self.width_s = pulse_width_s
        self.fading_std_db = fading_std_db
        self.options = options
        self.noise_dbm_hz = sensitivity_db - NOISE_BELOW_SENSITIVITY_DB
        r_noise, r_tags, self._rng_fade, self._dither_rng = rng.spawn(4)
        self._noise_rng = r_noise
        self._tag_offset = r_tags.normal(0.0, options.offset_std_hz, self.freqs.size)
        self._drift_period = r_tags.uniform(120.0, 300.0, self.freqs.size)
        self._drift_phase = r_tags.uniform(0.0, 2 * np.pi, self.freqs.size)
        self.rate_hz = DEFAULT_RATE_HZ
        self.centre_hz = float(self.freqs.mean())
        self.gain_db = 0.0
        self._noise_u8: np.ndarray | None = None
        self._t0: float | None = None
        self._sent = 0
        self._pending: list[tuple[float, float, float]] = []  # start sample, power_fs, offset
        self.stats = {"pulses": 0, "samples": 0, "dropped_samples": 0, "commands": 0}

    # -- the client's commands -----------------------------------------------------------

    def command(self, cmd: int, value: int, now_s: float) -> None:
        self.stats["commands"] += 1
        if cmd == rtltcp.SET_SAMPLE_RATE and value > 0 and value != self.rate_hz:
            self.rate_hz = float(value)
            self._noise_u8 = None
            self.restart(now_s)
        elif cmd == rtltcp.SET_FREQ and value > 0:
            self.centre_hz = float(value)
        elif cmd == rtltcp.SET_GAIN:
            self.gain_db = value / 10.0

    def stop(self) -> None:
        """No client: nothing is rendered until the next one connects."""
        self._t0 = None
        self._pending.clear()

    def restart(self, now_s: float) -> None:
        """Sample 0 of the stream is now."""
        self._t0 = now_s
        self._sent = 0
        self._pending.clear()

    # -- pulses ---------------------------------------------------------------------------

    def pulse(self, tag_index: int, t_s: float, power_dbm: float) -> None:
        """A pulse of tag ``tag_index`` starting at sim time ``t_s`` with noiseless power."""
        if self._t0 is None:
            return
        faded = power_dbm + float(self._rng_fade.normal(0.0, self.fading_std_db))
        drift = self.options.drift_hz * math.sin(
            2 * math.pi * t_s / self._drift_period[tag_index] + self._drift_phase[tag_index])
        offset = (self.freqs[tag_index] + self._tag_offset[tag_index] + drift - self.centre_hz)
        start = (t_s - self._t0) * self.rate_hz
        self._pending.append((start, self._power_fs(faded), float(offset)))
        self.stats["pulses"] += 1

    def _power_fs(self, dbm: float) -> float:
        return 10.0 ** ((dbm + self.gain_db - CAL_OFFSET_DB) / 10.0)

    # -- samples -------------------------------------------------------------------------------

    def render(self, now_s: float) -> bytes:
        """cu8 bytes of the stream from where it stopped up to sim time ``now_s``."""
        if self._t0 is None:
            return b""
        upto = math.floor((now_s - self._t0) * self.rate_hz)
        n = upto - self._sent
        if n <= 0:
            return b""
        first = self._sent
        self._sent = upto
        self.stats["samples"] += n
        out = self._noise(n)
        width = self.width_s * self.rate_hz
        active = [p for p in self._pending if p[0] < upto and p[0] + width > first]
        cw = self.options.cw_offset_hz
        if cw is not None:
            out = self._add(out, first, active, cw)
        else:
            for p in active:
                a = max(0, math.floor(p[0]) - first)
                b = min(n, math.ceil(p[0] + width) - first)
                out[2 * a: 2 * b] = self._add(out[2 * a: 2 * b], first + a, [p], None)
        self._pending = [p for p in self._pending if p[0] + width > upto]
        return out.tobytes()

    def _add(self, u8: np.ndarray, first: int,
             pulses: list[tuple[float, float, float]], cw: float | None) -> np.ndarray:
        """cu8 samples from ``first`` on, with the pulses and the CW tone added,
        re-quantised with half an LSB of uniform dither (without it, a weak tone added to
        already quantised noise would be quantised undithered and grow harmonics)."""
        x = synth.from_cu8(u8)
        width = self.width_s * self.rate_hz
        for start, power, offset in pulses:
            synth.add_tone(x, first, power, offset, self.rate_hz, phase=start,
                           start=start, stop=start + width)
        if cw is not None:
            synth.add_tone(x, first, self._power_fs(self.options.cw_dbm),
                           self.freqs[0] + cw - self.centre_hz, self.rate_hz)
        v = x.view(np.float32)
        v += self._dither_rng.uniform(-0.5 / 127.5, 0.5 / 127.5, v.size).astype(np.float32)
        return synth.to_cu8(x)

    def _noise(self, n: int) -> np.ndarray:
        if self._noise_u8 is None:
            power_fs = self._power_fs(self.noise_dbm_hz + 10 * math.log10(self.rate_hz))
            x = synth.noise(NOISE_BUFFER_SAMPLES, power_fs, self._noise_rng)
            self._noise_u8 = synth.to_cu8(x)
        buf = self._noise_u8
        size = buf.size // 2
        parts = []
        while n > 0:
            start = int(self._noise_rng.integers(0, size))
            take = min(n, size - start)
            parts.append(buf[2 * start: 2 * (start + take)])
            n -= take
        return np.concatenate(parts) if len(parts) > 1 else parts[0].copy()


class IqServer(asyncio.Protocol):
    """One rtl_tcp client at a time: sends the header, parses commands, streams samples."""

    def __init__(self, radio: IqRadio, now: Callable[[], float]) -> None:
        self.radio = radio
        self.now = now
        self.transport: asyncio.Transport | None = None
        self._buf = b""
        self.clients = 0

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        if self.transport is not None and not self.transport.is_closing():
            transport.close()  # one client, as rtl_tcp
            return
        self.transport = transport
        self.clients += 1
        transport.write(struct.pack(">4sII", rtltcp.MAGIC, rtltcp.TUNER_R820T,
                                    len(rtltcp.R820T_GAINS_TENTHS_DB)))
        self.radio.restart(self.now())

    def connection_lost(self, exc: Exception | None) -> None:
        self.transport = None
        self.radio.stop()

    def data_received(self, data: bytes) -> None:
        self._buf += data
        while len(self._buf) >= 5:
            cmd, value = rtltcp.unpack_command(self._buf[:5])
            self._buf = self._buf[5:]
            self.radio.command(cmd, value, self.now())

    def pump(self) -> None:
        """Send the stream up to now; drop the block if the client is too far behind."""
        data = self.radio.render(self.now())
        if not data or self.transport is None or self.transport.is_closing():
            return
        if self.transport.get_write_buffer_size() > MAX_QUEUE_S * 2 * self.radio.rate_hz:
            self.radio.stats["dropped_samples"] += len(data) // 2
            return
        with contextlib.suppress(OSError):
            self.transport.write(data)

