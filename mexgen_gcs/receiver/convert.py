"""Raw sample formats to complex64 full scale (1 = the converter's largest magnitude), with a
per-sample flag where I or Q sat at the converter's limit (clipping).

cu8: interleaved unsigned 8-bit (RTL-SDR, rtl_tcp); cs16: interleaved signed 16-bit
little-endian; cf32: interleaved float32 little-endian (already full scale; |I| or |Q| >= 1 is
flagged).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

#: bytes per complex sample of each format
SAMPLE_BYTES = {"cu8": 2, "cs16": 4, "cf32": 8}
#: SigMF core:datatype of each format
SIGMF_TYPES = {"cu8": "cu8", "cs16": "ci16_le", "cf32": "cf32_le"}


def _cu8_tables() -> tuple[NDArray[np.complex64], NDArray[np.bool_]]:
    """Every little-endian (I, Q) byte pair as one uint16 -> its sample and clipping flag."""
    v = np.arange(65536, dtype=np.uint32)
    i, q = (v & 0xFF).astype(np.float32), (v >> 8).astype(np.float32)
    samples = ((i - 127.5) / 127.5 + 1j * (q - 127.5) / 127.5).astype(np.complex64)
    clip = (i == 0) | (i == 255) | (q == 0) | (q == 255)
    return samples, clip


_CU8_SAMPLES, _CU8_CLIP = _cu8_tables()


def convert(raw: bytes | NDArray[np.uint8], fmt: str) -> tuple[NDArray[np.complex64],
                                                                 NDArray[np.bool_]]:
    """(samples, clipped) from whole samples of ``fmt`` (a partial last sample is ignored)."""
    if fmt not in SAMPLE_BYTES:
        raise ValueError(f"unknown sample format {fmt!r}; expected one of {sorted(SAMPLE_BYTES)}")
    buf = np.frombuffer(raw, dtype=np.uint8)
    size = SAMPLE_BYTES[fmt]
    buf = buf[: buf.size - buf.size % size]
    if fmt == "cu8":  # one table look-up per sample
        pairs = buf.view("<u2")
        return _CU8_SAMPLES[pairs], _CU8_CLIP[pairs]
    if fmt == "cs16":
        i16 = buf.view("<i2")
        lim = (i16 == -32768) | (i16 == 32767)
        v = i16.astype(np.float32) * np.float32(1.0 / 32768.0)
    else:
        v = buf.view("<f4").astype(np.float32)
        lim = np.abs(v) >= 1.0
    clipped = lim.reshape(-1, 2).any(axis=1)
    return v.view(np.complex64), clipped
