"""Radios on this machine: an RTL-SDR through pyrtlsdr, anything SoapySDR drives.

Both are optional: pyrtlsdr comes with the ``rtlsdr`` extra (``pip install
'mexgen-gcs[rtlsdr]'``, which brings a bundled librtlsdr); SoapySDR's Python bindings come
from the operating system (e.g. ``apt install python3-soapysdr`` plus a driver module). When
they are missing, opening the source raises a SourceError that says what to install.

pyrtlsdr's blocking ``read_bytes`` numbers no samples; a buffer lost in USB shows as a gap
against the clock (``pipeline``). SoapySDR's ``readStream`` reports overflows, which become
``lost_before`` (the number of samples lost is estimated from the stream's time stamps when the
driver gives them, else from the clock).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mexgen_gcs.receiver.calibration import R820T_GAINS_TENTHS_DB
from mexgen_gcs.receiver.convert import convert
from mexgen_gcs.receiver.sources import IQBlock, SourceError, Tuning


class PyRtlSdrSource:
    """An RTL-SDR dongle on USB, by device index."""

    live = True
    fixed: Tuning | None = None
    sets_ppm = True

    def __init__(self, index: int) -> None:
        self.name = f"rtlsdr://{index}"
        try:
            from rtlsdr import RtlSdr  # type: ignore[import-not-found, unused-ignore]
        except ImportError as exc:
            raise SourceError(f"{self.name}: pyrtlsdr is not installed ({exc}); install the "
                              "extra: pip install 'mexgen-gcs[rtlsdr]'") from None
        try:
            self._sdr: Any = RtlSdr(device_index=index)
        except Exception as exc:  # librtlsdr raises its own types (LibUSBError, IOError...)
            raise SourceError(f"{self.name}: cannot open the dongle: {exc}") from None
        gains = getattr(self._sdr, "valid_gains_db", None) or []
        self.gain_table: tuple[int, ...] | None = (
            tuple(round(float(g) * 10) for g in gains) if gains else R820T_GAINS_TENTHS_DB)

    def tune(self, tuning: Tuning) -> None:
        try:
            self._sdr.sample_rate = tuning.rate_hz
            if tuning.ppm:
                self._sdr.freq_correction = round(tuning.ppm)
            self._sdr.center_freq = tuning.centre_hz
            self._sdr.set_manual_gain_enabled(True)
            self._sdr.set_agc_mode(False)
            self._sdr.gain = tuning.gain_db
        except Exception as exc:
            raise SourceError(f"{self.name}: cannot configure: {exc}") from None

    def read(self, max_samples: int) -> IQBlock | None:
        n = max(512, (2 * max_samples) // 512 * 512)
        try:
            raw = bytes(self._sdr.read_bytes(n))
        except Exception as exc:
            raise SourceError(f"{self.name}: read failed: {exc}") from None
        samples, clipped = convert(raw, "cu8")
        return IQBlock(samples, clipped, raw, "cu8")

    def close(self) -> None:
        self._sdr.close()


class SoapySource:
    """Any radio SoapySDR can open, from its device arguments (``driver=airspy,serial=...``)."""

    live = True
    fixed: Tuning | None = None
    sets_ppm = True
    gain_table: tuple[int, ...] | None = None

    def __init__(self, args: str) -> None:
        self.name = f"soapy://{args}"
        try:
            import SoapySDR  # type: ignore[import-not-found, unused-ignore]
        except ImportError:
            raise SourceError(f"{self.name}: SoapySDR's Python bindings are not installed; "
                              "they come from the system (e.g. apt install python3-soapysdr "
                              "and the radio's Soapy module)") from None
        self._soapy: Any = SoapySDR
        try:
            self._dev: Any = SoapySDR.Device(args)
        except Exception as exc:
            raise SourceError(f"{self.name}: cannot open the device: {exc}") from None
        self._stream: Any = None

    def tune(self, tuning: Tuning) -> None:
        s, rx = self._soapy, self._soapy.SOAPY_SDR_RX
        try:
            self._dev.setSampleRate(rx, 0, tuning.rate_hz)
            self._dev.setFrequency(rx, 0, tuning.centre_hz)
            if tuning.ppm and self._dev.hasFrequencyCorrection(rx, 0):
                self._dev.setFrequencyCorrection(rx, 0, tuning.ppm)
            self._dev.setGainMode(rx, 0, False)
            self._dev.setGain(rx, 0, tuning.gain_db)
            self._stream = self._dev.setupStream(rx, s.SOAPY_SDR_CF32)
            self._dev.activateStream(self._stream)
        except Exception as exc:
            raise SourceError(f"{self.name}: cannot configure: {exc}") from None
        self._rate = tuning.rate_hz
        self._last_ns: int | None = None

    def read(self, max_samples: int) -> IQBlock | None:
        buf = np.empty(max_samples, np.complex64)
        res = self._dev.readStream(self._stream, [buf], max_samples, timeoutUs=1_000_000)
        lost = 0
        if res.ret == self._soapy.SOAPY_SDR_OVERFLOW:
            lost = -1  # unknown amount: the clock check measures it
            res = self._dev.readStream(self._stream, [buf], max_samples, timeoutUs=1_000_000)
        if res.ret < 0:
            raise SourceError(f"{self.name}: readStream error {res.ret}")
        samples = buf[: res.ret]
        raw = samples.tobytes()
        samples, clipped = convert(raw, "cf32")
        return IQBlock(samples, clipped, raw, "cf32", lost_before=max(lost, 0))

    def close(self) -> None:
        if self._stream is not None:
            self._dev.deactivateStream(self._stream)
            self._dev.closeStream(self._stream)
