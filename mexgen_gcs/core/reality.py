"""Reality profiles: radio worlds that differ from the mission's model, defined once.

Frame: local ENU metres about home (x east, y north, z up); tags are near the ground (z = 0
unless the ``terrain`` profile lifts or lowers them); yaw is a compass heading in radians
(0 = north, clockwise), as in :mod:`core.radio`.

The mission's :class:`~mexgen_gcs.core.radio.RadioModel` is what the ground station believes.
A :class:`RealityProfile` says how the world differs from it, and :meth:`RealityProfile.realise`
draws one world (a :class:`TrueRadio`) from it with an explicit generator: per-tag transmit
offsets, the path-loss exponent, tag heights, the compass bias and one shadowing field per tag.
The simulator (``sim.radios``, mission key ``sim.reality``) and the experiment world
(``mexgen-gcs experiment ... --reality NAME``) both use this module, so a profile means the same
thing everywhere.

True received power of tag ``i`` at receiver pose ``(u, yaw)``::

    P = P0 + o_i - 10 n log10(max(d, d_min) / d0) + g_true(bearing - yaw - bias, elev) + S_i(u)

``d`` is the 3-D distance to the tag at height ``h_i``, ``o_i`` the tag's transmit offset, ``n``
the world's exponent, ``g_true`` the world's antenna pattern (the mission's monopole pattern in
every profile but ``antenna``), ``bias`` the compass bias (the reported yaw is off by it) and
``S_i`` a zero-mean Gaussian field over the receiver position with exponential correlation
``exp(-|u - u'| / L)`` (Gudmundson's model of shadowing). Each pulse then fades: the power
gain of a Rician channel with factor ``K`` (``K = 0``: Rayleigh) multiplies the received power
(adds ``10 log10 |h|^2`` dB, ``E|h|^2 = 1``); detection follows the receiver's probit model on
that faded power, and the reported RSSI adds the receiver noise ``N(0, noise_std_db^2)``.

Profiles (``PROFILES``; parameter sources in each profile's ``source``):

========== ====================================================================================
matched    the mission's model exactly
tx-power   per-tag transmit offset uniform in +-6 dB (collar batteries, tuning, antennas)
path-loss  exponent uniform in [1.2, 2.2] per world (open ground to vegetation)
antenna    a pattern the mission does not model: +2 dB ahead / -2 dB behind, pointing 20 deg
           off the nose, with a 0.75 dB two-lobe term (an airframe-mounted monopole)
shadowing  log-normal shadowing, 4 dB, exponential correlation over 50 m
fading     per-pulse Rician fading, K = 6 dB
terrain    tags up to +-30 m above or below the home plane
compass    heading bias uniform in +-10 deg
field      all of the above at once
========== ====================================================================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mexgen_gcs.core.radio import RadioModel

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

SHADOWING_FEATURES = 256
"""Random Fourier features per shadowing field (accuracy of the exponential covariance)."""


@dataclass(frozen=True, slots=True)
class AntennaPattern:
    """A receiver antenna gain pattern, dB, as a short Fourier series in the relative bearing::

        g(dpsi, elev) = (a0 + a1 (cos(dpsi - phi1) - 1) + a2 (cos(2 (dpsi - phi2)) - 1)) cos(elev)

    ``dpsi`` is the tag's bearing relative to the antenna's nose, ``elev`` the depression angle.
    The mission's monopole model is ``a0 = 0, a1 = front_back_db / 2``.
    """

    a0_db: float = 0.0
    a1_db: float = 1.5
    phi1_deg: float = 0.0
    a2_db: float = 0.0
    phi2_deg: float = 0.0

    @classmethod
    def of_model(cls, radio: RadioModel) -> AntennaPattern:
        return cls(a1_db=0.5 * radio.front_back_db)

    def gain_db(self, cos_elev: FloatArray, rel_bearing_rad: FloatArray) -> FloatArray:
        """Gain for (...) arrays of cos(elevation) and relative bearing; (...) float64."""
        p1, p2 = math.radians(self.phi1_deg), math.radians(self.phi2_deg)
        g = (self.a0_db + self.a1_db * (np.cos(rel_bearing_rad - p1) - 1.0)
             + self.a2_db * (np.cos(2.0 * (rel_bearing_rad - p2)) - 1.0))
        return g * cos_elev


@dataclass(frozen=True, slots=True)
class RealityProfile:
    """How the world's radio differs from the mission's model (all zero = matched)."""

    name: str
    tx_offset_db: float = 0.0
    """Per-tag transmit offset, uniform in [-x, x] dB."""
    path_loss_exponent: tuple[float, float] | None = None
    """The world's exponent, uniform in [lo, hi]; None = the mission's."""
    antenna: AntennaPattern | None = None
    """The world's antenna pattern; None = the mission's monopole pattern."""
    shadowing_std_db: float = 0.0
    shadowing_distance_m: float = 50.0
    """Correlation distance L of the shadowing field, exp(-d / L)."""
    rician_k_db: float | None = None
    """Per-pulse Rician fading factor K in dB (-inf = Rayleigh); None = no fading."""
    terrain_m: float = 0.0
    """Tag heights uniform in [-x, x] m about the home plane."""
    compass_bias_deg: float = 0.0
    """Heading bias uniform in [-x, x] deg per world (the reported yaw is off by it)."""
    source: str = ""
    """Where the parameter values come from."""

    def realise(self, radio: RadioModel, n_tags: int, rng: np.random.Generator) -> TrueRadio:
        """Draw one world for ``n_tags`` tags. Always draws the same numbers in the same order
        whatever the profile, so two profiles with one seed share what they have in common."""
        u = rng.uniform(-1.0, 1.0, size=(4, n_tags))
        offsets = self.tx_offset_db * u[0]
        heights = self.terrain_m * u[1]
        lo, hi = self.path_loss_exponent or (radio.path_loss_exponent,) * 2
        exponent = lo + (hi - lo) * 0.5 * (u[2, 0] + 1.0)
        bias = math.radians(self.compass_bias_deg * u[3, 0])
        shadow = ShadowingField.draw(n_tags, self.shadowing_std_db, self.shadowing_distance_m,
                                     rng)
        antenna = self.antenna or AntennaPattern.of_model(radio)
        k_lin = None if self.rician_k_db is None else 10.0 ** (self.rician_k_db / 10.0)
        return TrueRadio(radio, self, offsets, heights, float(exponent), bias, antenna, shadow,
                         k_lin)

    def describe(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for name in self.__slots__:
            v = getattr(self, name)
            out[name] = v if not isinstance(v, AntennaPattern) else {
                k: getattr(v, k) for k in v.__slots__}
        return out


_FIELD_ANTENNA = AntennaPattern(a0_db=2.0, a1_db=2.0, phi1_deg=20.0, a2_db=0.75, phi2_deg=0.0)

_PROFILES = (
    RealityProfile("matched", source="the mission's model (paper section 4)"),
    RealityProfile("tx-power", tx_offset_db=6.0,
                   source="collar transmit power varies by several dB between tags"),
    RealityProfile("path-loss", path_loss_exponent=(1.2, 2.2),
                   source="exponent of open ground (~1.2 near line of sight at VHF) to "
                          "vegetation and terrain (~2.2)"),
    RealityProfile("antenna", antenna=_FIELD_ANTENNA,
                   source="airframe-mounted monopole: pattern only roughly known, 1-2 dB off "
                          "the 0/-3 dB model with a pointing error"),
    RealityProfile("shadowing", shadowing_std_db=4.0, shadowing_distance_m=50.0,
                   source="log-normal shadowing with Gudmundson's exponential correlation"),
    RealityProfile("fading", rician_k_db=6.0,
                   source="per-pulse Rician multipath fading with a line-of-sight component"),
    RealityProfile("terrain", terrain_m=30.0,
                   source="tags on hilly ground, up to 30 m off the home plane"),
    RealityProfile("compass", compass_bias_deg=10.0,
                   source="magnetometer heading bias of a multirotor"),
)
_FIELD = replace(
    _PROFILES[0], name="field", tx_offset_db=6.0, path_loss_exponent=(1.2, 2.2),
    antenna=_FIELD_ANTENNA, shadowing_std_db=4.0, rician_k_db=6.0, terrain_m=30.0,
    compass_bias_deg=10.0, source="all of the other profiles at once")

PROFILES: MappingProxyType[str, RealityProfile] = MappingProxyType(
    {p.name: p for p in (*_PROFILES, _FIELD)})
"""Every named reality profile."""


def profile(name: str) -> RealityProfile:
    """The named profile; ValueError naming the choices otherwise."""
    try:
        return PROFILES[name]
    except KeyError:
        raise ValueError(f"unknown reality profile {name!r}; expected one of "
                         f"{', '.join(PROFILES)}") from None


@dataclass(frozen=True, slots=True, eq=False)
class ShadowingField:
    """One zero-mean Gaussian field per tag over the receiver's horizontal position, with
    covariance ``std^2 exp(-|du| / L)``, as a sum of random Fourier features (the spectral
    density of the 2-D exponential kernel is a bivariate Student t with one degree of freedom,
    scaled by 1 / L)."""

    std_db: float
    omega: FloatArray
    """(n_tags, F, 2) spatial frequencies, rad/m."""
    phase: FloatArray
    """(n_tags, F) phases."""

    @classmethod
    def draw(cls, n_tags: int, std_db: float, distance_m: float,
             rng: np.random.Generator, features: int = SHADOWING_FEATURES) -> ShadowingField:
        g = rng.standard_normal((n_tags, features, 2))
        chi = np.maximum(rng.chisquare(1.0, (n_tags, features, 1)), 1e-12)
        omega = g / (distance_m * np.sqrt(chi))
        phase = rng.uniform(0.0, 2.0 * math.pi, (n_tags, features))
        return cls(float(std_db), omega, phase)

    def at(self, tag: IntArray | int, rx_xy: FloatArray) -> FloatArray:
        """Shadowing (dB) of ``tag`` (...) at receiver positions rx_xy (..., 2)."""
        if self.std_db == 0.0:
            return np.zeros(np.broadcast_shapes(np.shape(tag), np.shape(rx_xy)[:-1]))
        om = self.omega[tag]  # (..., F, 2)
        arg = np.einsum("...fk,...k->...f", om, np.asarray(rx_xy, dtype=np.float64))
        arg += self.phase[tag]
        scale = self.std_db * math.sqrt(2.0 / self.omega.shape[1])
        return scale * np.cos(arg).sum(axis=-1)


@dataclass(frozen=True, slots=True, eq=False)
class TrueRadio:
    """One drawn radio world (see the module docstring). Pure: randomness per call comes from
    the generator passed in."""

    model: RadioModel
    """The mission's model (receiver noise, detection threshold, P0, d0)."""
    profile: RealityProfile
    tx_offset_db: FloatArray
    """(n_tags,) transmit offsets, dB."""
    tag_height_m: FloatArray
    """(n_tags,) tag heights above the home plane, m."""
    path_loss_exponent: float
    compass_bias_rad: float
    antenna: AntennaPattern
    shadowing: ShadowingField
    rician_k: float | None
    """Linear Rician factor, None without fading."""

    def mean_power_db(self, tag: IntArray | int, tag_xy: FloatArray, rx_xyz: FloatArray,
                      reported_yaw_rad: FloatArray | float) -> FloatArray:
        """Local-mean received power (no fading, no receiver noise), dB.

        tag: (...) tag indices; tag_xy: (..., 2); rx_xyz: (..., 3); reported_yaw_rad: the
        heading the vehicle reports (the true heading is off by the compass bias)."""
        m = self.model
        tag = np.asarray(tag)
        dx = tag_xy[..., 0] - rx_xyz[..., 0]
        dy = tag_xy[..., 1] - rx_xyz[..., 1]
        dz = self.tag_height_m[tag] - rx_xyz[..., 2]
        horiz = np.sqrt(dx * dx + dy * dy)
        dist = np.sqrt(np.maximum(horiz * horiz + dz * dz, m.min_distance_m**2))
        power = (m.p0_db + self.tx_offset_db[tag]
                 - 10.0 * self.path_loss_exponent * np.log10(dist / m.d0_m))
        yaw = np.asarray(reported_yaw_rad) + self.compass_bias_rad
        bearing = np.arctan2(dx, dy)  # compass bearing to the tag
        power = power + self.antenna.gain_db(horiz / dist, bearing - yaw)
        return power + self.shadowing.at(tag, rx_xyz[..., :2])

    def fading_db(self, shape: tuple[int, ...], rng: np.random.Generator) -> FloatArray:
        """Per-pulse fading gains, dB (E of the linear gain = 1). Always draws two normals per
        pulse, so the number of draws does not depend on the profile."""
        g = rng.standard_normal((*shape, 2))
        if self.rician_k is None:
            return np.zeros(shape)
        k = self.rician_k
        los = math.sqrt(k / (k + 1.0))
        scatter = math.sqrt(0.5 / (k + 1.0))
        re = los + scatter * g[..., 0]
        im = scatter * g[..., 1]
        return 10.0 * np.log10(np.maximum(re * re + im * im, 1e-12))

    def pulse(self, tag: IntArray | int, tag_xy: FloatArray, rx_xyz: FloatArray,
              reported_yaw_rad: FloatArray | float, rng: np.random.Generator
              ) -> tuple[FloatArray, NDArray[np.bool_], FloatArray]:
        """One pulse of each tag: (instantaneous power dB, detected, reported RSSI dB).

        A fixed number of draws per pulse: two fading normals, one detection uniform and one
        receiver-noise normal per tag, whatever the profile and the pose."""
        mean = self.mean_power_db(tag, tag_xy, rx_xyz, reported_yaw_rad)
        power = mean + self.fading_db(np.shape(mean), rng)
        detected = self.model.detect(power, rng)
        rssi = self.model.measure(power, rng)
        return power, detected, rssi
