"""From digital power to dBm: fixed tuner gain, the device's gain table, a calibration offset.

Digital power is in dB full scale (dBFS): a complex sample of magnitude 1 is 0 dBFS. The
receiver runs with AGC off and one fixed tuner gain, so the power at the antenna is::

    P_dBm = P_dBFS - gain_db + cal_offset_db

``cal_offset_db`` is what one measurement against a known source gives (docs/receiver.md):
feed a signal of known level S_dBm, read the reported dBFS at the gain used, and
``cal_offset_db = S_dBm - (P_dBFS - gain_db)``. A tuner only has certain gains; the requested
one is rounded to the nearest entry of the device's table, and that is the one used in the
conversion.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: R820T/R828D tuner gains in tenths of dB, as librtlsdr lists them (rtl_tcp reports the count).
R820T_GAINS_TENTHS_DB: tuple[int, ...] = (
    0, 9, 14, 27, 37, 77, 87, 125, 144, 157, 166, 197, 207, 229, 254, 280, 297, 328, 338, 364,
    372, 386, 402, 421, 434, 439, 445, 480, 496)

GAIN_TABLES: dict[str, tuple[int, ...]] = {"r820t": R820T_GAINS_TENTHS_DB}


def nearest_gain_db(requested_db: float, table: tuple[int, ...] | None) -> float:
    """The table's gain nearest to the request (the request itself without a table)."""
    if not table:
        return requested_db
    tenths = min(table, key=lambda g: abs(g - requested_db * 10.0))
    return tenths / 10.0


@dataclass(frozen=True, slots=True)
class Calibration:
    """Fixed gain and calibration offset of one device."""

    gain_db: float = 0.0
    cal_offset_db: float = 0.0
    device: str = "uncalibrated"

    def dbm(self, power_fs: float) -> float:
        """Linear power over full scale -> dBm at the antenna (-inf for 0)."""
        if power_fs <= 0.0:
            return -math.inf
        return 10.0 * math.log10(power_fs) - self.gain_db + self.cal_offset_db

    def power_fs(self, dbm: float) -> float:
        """dBm at the antenna -> linear power over full scale (the inverse of `dbm`)."""
        return 10.0 ** ((dbm + self.gain_db - self.cal_offset_db) / 10.0)
