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


def convert(raw: bytes | NDArray[np.uint8], fmt: str) -> tuple[NDArray[np.complex64],
                                                                 NDArray[np.bool_]]:
    """(samples, clipped) from whole samples of ``fmt`` (a partial last sample is ignored)."""
    buf = np.frombuffer(raw, dtype=np.uint8)
    size = SAMPLE_BYTES[fmt]
    buf = buf[: buf.size - buf.size % size]
    if fmt == "cu8":
        lim = (buf == 0) | (buf == 255)
        v = buf.astype(np.float32)
        v -= np.float32(127.5)
        v *= np.float32(1.0 / 127.5)
    elif fmt == "cs16":
        i16 = buf.view("<i2")
        lim = (i16 == -32768) | (i16 == 32767)
        v = i16.astype(np.float32) * np.float32(1.0 / 32768.0)
    elif fmt == "cf32":
        v = buf.view("<f4").astype(np.float32)
        lim = np.abs(v) >= 1.0
    else:
        raise ValueError(f"unknown sample format {fmt!r}; expected one of {sorted(SAMPLE_BYTES)}")
    clipped = lim.reshape(-1, 2).any(axis=1)
    return v.view(np.complex64), clipped
