"""Geodetic frames: WGS84 (lat, lon, alt) <-> local ENU metres anchored at the mission home.

ENU: x east, y north, z up, metres, origin at home (``alt0_m`` is home's altitude AMSL /
ellipsoid, whichever the caller uses consistently). Conversions use pymap3d (WGS84 ellipsoid).
NED, as MAVLink uses it, is (north, east, down) = (y, x, -z); helpers convert velocities and
headings between the two.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pymap3d
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class LocalFrame:
    """A local ENU frame anchored at (lat0_deg, lon0_deg, alt0_m). Vectorised conversions."""

    lat0_deg: float
    lon0_deg: float
    alt0_m: float = 0.0

    def __post_init__(self) -> None:
        if not (-90.0 <= self.lat0_deg <= 90.0 and -180.0 <= self.lon0_deg <= 180.0):
            raise ValueError(f"home ({self.lat0_deg}, {self.lon0_deg}) is not a valid lat/lon")

    def to_enu(
        self, lat_deg: ArrayLike, lon_deg: ArrayLike, alt_m: ArrayLike = 0.0
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(lat, lon, alt) -> (east_m, north_m, up_m); inputs broadcast."""
        e, n, u = pymap3d.geodetic2enu(
            np.asarray(lat_deg, dtype=np.float64), np.asarray(lon_deg, dtype=np.float64),
            np.asarray(alt_m, dtype=np.float64), self.lat0_deg, self.lon0_deg, self.alt0_m,
        )
        return np.asarray(e), np.asarray(n), np.asarray(u)

    def to_geodetic(
        self, east_m: ArrayLike, north_m: ArrayLike, up_m: ArrayLike = 0.0
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(east_m, north_m, up_m) -> (lat_deg, lon_deg, alt_m); inputs broadcast."""
        lat, lon, alt = pymap3d.enu2geodetic(
            np.asarray(east_m, dtype=np.float64), np.asarray(north_m, dtype=np.float64),
            np.asarray(up_m, dtype=np.float64), self.lat0_deg, self.lon0_deg, self.alt0_m,
        )
        return np.asarray(lat), np.asarray(lon), np.asarray(alt)


def heading_to_enu_unit(heading_deg: ArrayLike) -> FloatArray:
    """Compass heading (0 = north, clockwise) -> ENU unit vector (..., 2) [east, north]."""
    h = np.radians(np.asarray(heading_deg, dtype=np.float64))
    return np.stack([np.sin(h), np.cos(h)], axis=-1)


def enu_to_heading_deg(east: ArrayLike, north: ArrayLike) -> FloatArray:
    """ENU direction -> compass heading in [0, 360) degrees."""
    return np.mod(np.degrees(np.arctan2(east, north)), 360.0)


def velocity_enu_to_ned(v_east_m_s: float, v_north_m_s: float, v_up_m_s: float = 0.0
                        ) -> tuple[float, float, float]:
    """ENU velocity -> MAVLink NED velocity (north, east, down)."""
    return v_north_m_s, v_east_m_s, -v_up_m_s


def wrap_deg(angle_deg: float) -> float:
    """Wrap an angle to (-180, 180] degrees."""
    a = math.fmod(angle_deg + 180.0, 360.0)
    if a <= 0.0:
        a += 360.0
    return a - 180.0
