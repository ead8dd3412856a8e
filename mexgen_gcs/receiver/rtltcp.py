"""The rtl_tcp protocol (the standard one of librtlsdr's rtl_tcp) and a client source.

On connect the server sends a 12-byte dongle info header: the magic ``RTL0``, the tuner type
(uint32 big-endian) and the number of gain steps (uint32 big-endian); then it streams
interleaved unsigned 8-bit I/Q. The client sends 5-byte commands: one command byte and a
uint32 big-endian parameter (`pack_command`). rtl_tcp numbers no samples: a server that falls
behind drops buffers silently, which the receiver's clock check detects (``pipeline``).
"""

from __future__ import annotations

import socket
import struct
import time

from mexgen_gcs.receiver.calibration import R820T_GAINS_TENTHS_DB
from mexgen_gcs.receiver.convert import convert
from mexgen_gcs.receiver.sources import IQBlock, SourceError, Tuning

MAGIC = b"RTL0"
HEADER = struct.Struct(">4sII")
COMMAND = struct.Struct(">BI")

SET_FREQ = 0x01
SET_SAMPLE_RATE = 0x02
SET_GAIN_MODE = 0x03  # 0 = automatic (AGC in the tuner), 1 = manual
SET_GAIN = 0x04  # tenths of dB
SET_FREQ_CORRECTION = 0x05  # ppm, signed as uint32
SET_IF_GAIN = 0x06
SET_TEST_MODE = 0x07
SET_AGC_MODE = 0x08  # the RTL2832's digital AGC: 0 off
SET_DIRECT_SAMPLING = 0x09
SET_OFFSET_TUNING = 0x0A
SET_GAIN_BY_INDEX = 0x0D

TUNER_R820T = 5
SETTLE_S = 0.25
TUNER_NAMES = {1: "e4000", 2: "fc0012", 3: "fc0013", 4: "fc2580", 5: "r820t", 6: "r828d"}


def pack_command(command: int, param: int) -> bytes:
    """One 5-byte command; negative parameters (ppm) are sent as their two's complement."""
    return COMMAND.pack(command, param & 0xFFFFFFFF)


def unpack_command(data: bytes) -> tuple[int, int]:
    """(command, signed parameter) of a 5-byte command."""
    cmd, value = COMMAND.unpack(data)
    return cmd, value - (1 << 32) if value & 0x80000000 else value


class RtlTcpSource:
    """Client of an rtl_tcp server at (host, port)."""

    live = True
    fixed: Tuning | None = None
    sets_ppm = True

    def __init__(self, host: str, port: int, timeout_s: float = 5.0) -> None:
        self.name = f"rtltcp://{host}:{port}"
        try:
            self._sock = socket.create_connection((host, port), timeout=timeout_s)
        except OSError as exc:
            raise SourceError(f"{self.name}: cannot connect: {exc}") from None
        header = self._recv_exact(HEADER.size)
        magic, tuner, ngains = HEADER.unpack(header)
        if magic != MAGIC:
            self.close()
            raise SourceError(f"{self.name}: not an rtl_tcp server (header {header[:4]!r})")
        self.tuner = TUNER_NAMES.get(tuner, f"tuner {tuner}")
        self.gain_count = ngains
        self.gain_table: tuple[int, ...] | None = R820T_GAINS_TENTHS_DB if tuner in (5, 6) else None
        self._leftover = b""
        self._sock.settimeout(timeout_s)

    def _recv_exact(self, n: int) -> bytes:
        data = b""
        while len(data) < n:
            try:
                chunk = self._sock.recv(n - len(data))
            except OSError as exc:
                raise SourceError(f"{self.name}: {exc}") from None
            if not chunk:
                raise SourceError(f"{self.name}: the server closed the connection")
            data += chunk
        return data

    def send(self, command: int, param: int) -> None:
        try:
            self._sock.sendall(pack_command(command, param))
        except OSError as exc:
            raise SourceError(f"{self.name}: {exc}") from None

    def tune(self, tuning: Tuning) -> None:
        """Fixed gain, AGCs off, then rate, ppm and centre."""
        self.send(SET_GAIN_MODE, 1)
        self.send(SET_AGC_MODE, 0)
        self.send(SET_GAIN, round(tuning.gain_db * 10.0))
        self.send(SET_SAMPLE_RATE, round(tuning.rate_hz))
        self.send(SET_FREQ_CORRECTION, round(tuning.ppm))
        self.send(SET_FREQ, round(tuning.centre_hz))
        self._settle()

    def _settle(self) -> None:
        """Discard what the server sent before the commands took effect (the old rate, gain
        and frequency, and the tuner's settling): ``SETTLE_S`` of reading."""
        end = time.monotonic() + SETTLE_S
        while time.monotonic() < end:
            try:
                if not self._sock.recv(1 << 16):
                    return
            except TimeoutError:
                return
            except OSError as exc:
                raise SourceError(f"{self.name}: {exc}") from None
        self._leftover = b""

    def read(self, max_samples: int) -> IQBlock | None:
        want = max(2, 2 * max_samples - len(self._leftover))
        try:
            chunk = self._sock.recv(want)
        except TimeoutError:
            raise SourceError(f"{self.name}: no samples for {self._sock.gettimeout():g} s") \
                from None
        except OSError as exc:
            raise SourceError(f"{self.name}: {exc}") from None
        if not chunk:
            return None
        data = self._leftover + chunk
        cut = len(data) - len(data) % 2
        raw, self._leftover = data[:cut], data[cut:]
        samples, clipped = convert(raw, "cu8")
        return IQBlock(samples, clipped, raw, "cu8")

    def close(self) -> None:
        self._sock.close()


