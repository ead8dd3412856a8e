"""Radio measurement and detection model (paper section 4, eq. range-measurement).

Frame: local ENU metres about the mission home (x east, y north, z up). Headings (`yaw_rad`)
are compass headings: 0 = north, pi/2 = east, clockwise positive, as MAVLink reports them.

Received power in dB at receiver position ``u`` from a tag at ``x``::

    P(x, u) = P0 - 10 n log10(max(||x - u||, d_min) / d0) + g_dir(x, u)

with 3-D distance (the vehicle flies at altitude, tags are on the ground at z = 0).

Antenna gain ``g_dir`` (monopole on the airframe): a vertical monopole is omnidirectional in
azimuth in free space, but mounted beside the airframe the body shadows the side away from it,
so the pattern is a smooth cardioid-like loss of up to ``front_back_db`` towards the tail::

    g_dir = (front_back_db / 2) * (cos(dpsi) - 1) * cos(elev)

where ``dpsi`` is the tag's bearing relative to the vehicle heading and ``elev`` the depression
angle from the receiver to the tag. The ``cos(elev)`` factor fades the directional effect out
as the tag gets directly below (where the bearing is undefined), so the model is continuous
and finite everywhere. Gain is 0 dB straight ahead, ``-front_back_db`` straight behind.

Detection model: the probability that a pulse is detected given the noiseless predicted
power is a smooth threshold around the receiver sensitivity::

    pD(P) = pd_max * Phi((P - sensitivity_db) / detection_spread_db)

Noise: a detected pulse is reported as ``P + zeta``, ``zeta ~ N(0, noise_std_db**2)``.
Clutter: spurious detections arrive at ``clutter_rate`` per pulse period, uniform in dB over
``[clutter_min_db, clutter_max_db]``.

All functions broadcast over leading axes: particles, actions, samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.special import ndtr

from mexgen_gcs.core.jit import inline

FloatArray = NDArray[np.float64]

_LOG_2PI = math.log(2.0 * math.pi)


@inline
def distance2_and_gain(dx: Any, dy: Any, dz2: Any, min2: Any, ks: Any, kc: Any,
                       half_fb: Any) -> tuple[Any, Any]:
    """:meth:`RadioModel.geometry` for one tag in a compiled kernel (any float type): the
    squared 3-D distance ``max(dx^2 + dy^2 + dz^2, d_min^2)`` and the antenna gain
    ``(fb / 2) (cos(bearing - yaw) cos(elev) - cos(elev))``, with the tag at (dx, dy)
    east/north of the receiver and dz2 the squared height difference; ks, kc = (fb / 2)
    sin(yaw), (fb / 2) cos(yaw); half_fb = fb / 2. The one implementation the filter's
    and the planner's kernels share (each takes its own logarithm of the distance)."""
    h2 = dx * dx + dy * dy
    d2 = max(h2 + dz2, min2)
    return d2, (dx * ks + dy * kc - half_fb * np.sqrt(h2)) / np.sqrt(d2)


@dataclass(frozen=True, slots=True)
class RadioModel:
    """Parameters of the received-power, noise and detection models (paper defaults)."""

    p0_db: float = -7.0
    """Received power at the reference distance d0, dB."""
    d0_m: float = 1.0
    """Reference distance, metres."""
    path_loss_exponent: float = 1.5
    """Path-loss exponent n (environment dependent)."""
    noise_std_db: float = 2.5
    """Standard deviation of the measurement noise; R = noise_std_db**2."""
    front_back_db: float = 3.0
    """Antenna front-to-back ratio: gain towards the tail relative to the nose, dB (>= 0)."""
    sensitivity_db: float = -60.0
    """Power at which half of pd_max of the pulses are detected, dB."""
    detection_spread_db: float = 2.0
    """Width of the detection threshold (probit scale), dB; > 0."""
    pd_max: float = 0.95
    """Detection probability far above the sensitivity."""
    min_distance_m: float = 1.0
    """Distances below this are clamped (keeps log10 finite with a tag at the antenna)."""
    clutter_rate: float = 0.01
    """Expected spurious detections per tag channel per pulse period."""
    clutter_min_db: float = -90.0
    clutter_max_db: float = 0.0

    def __post_init__(self) -> None:
        if not (self.noise_std_db > 0 and self.detection_spread_db > 0 and self.d0_m > 0):
            raise ValueError("noise_std_db, detection_spread_db and d0_m must be > 0")
        if not 0.0 <= self.pd_max <= 1.0:
            raise ValueError("pd_max must be in [0, 1]")
        if self.front_back_db < 0 or self.min_distance_m <= 0:
            raise ValueError("front_back_db must be >= 0 and min_distance_m > 0")
        if not self.clutter_max_db > self.clutter_min_db or self.clutter_rate < 0:
            raise ValueError("clutter range must be non-empty and clutter_rate >= 0")

    @property
    def noise_var(self) -> float:
        """R, the measurement noise variance (dB^2)."""
        return self.noise_std_db**2

    @property
    def clutter_density(self) -> float:
        """lambda * c(z): clutter intensity per dB, uniform over the clutter range."""
        return self.clutter_rate / (self.clutter_max_db - self.clutter_min_db)

    # -- noiseless model --------------------------------------------------------------------

    def geometry(
        self,
        tag_xy: FloatArray,
        rx_xyz: FloatArray,
        rx_yaw_rad: FloatArray | float,
        tag_z: FloatArray | float = 0.0,
    ) -> tuple[FloatArray, FloatArray]:
        """The two pose-dependent terms of the power, ``P = p0 + n * l + g``: the exponent's
        regressor ``l = -10 log10(max(d, d_min) / d0)`` and the antenna gain ``g`` (dB).

        Shapes as :meth:`power_db`; returns two (...) float64 arrays.
        """
        dx = tag_xy[..., 0] - rx_xyz[..., 0]
        dy = tag_xy[..., 1] - rx_xyz[..., 1]
        dz = tag_z - rx_xyz[..., 2]
        horiz2 = dx * dx + dy * dy
        dist = np.sqrt(np.maximum(horiz2 + dz * dz, self.min_distance_m**2))
        log_term = -10.0 * np.log10(dist / self.d0_m)
        if self.front_back_db > 0.0:
            # cos(bearing - yaw) * cos(elev) = (dx sin(yaw) + dy cos(yaw)) / dist
            # (compass bearing: east = sin, north = cos); finite when horiz == 0.
            cos_rel_times_cos_elev = (dx * np.sin(rx_yaw_rad) + dy * np.cos(rx_yaw_rad)) / dist
            cos_elev = np.sqrt(horiz2) / dist
            gain = 0.5 * self.front_back_db * (cos_rel_times_cos_elev - cos_elev)
        else:
            gain = np.zeros_like(log_term)
        return log_term, gain

    def power_db(
        self,
        tag_xy: FloatArray,
        rx_xyz: FloatArray,
        rx_yaw_rad: FloatArray | float,
        tag_z: FloatArray | float = 0.0,
    ) -> FloatArray:
        """Noiseless received power P(x, u), dB.

        tag_xy: (..., 2) tag east/north; rx_xyz: (..., 3) receiver east/north/up;
        rx_yaw_rad: (...) heading. All broadcast against each other; returns (...) float64.
        """
        log_term, gain = self.geometry(tag_xy, rx_xyz, rx_yaw_rad, tag_z)
        return self.p0_db + self.path_loss_exponent * log_term + gain

    def detection_probability(self, power_db: FloatArray) -> FloatArray:
        """pD given the noiseless power; (...) -> (...) in [0, pd_max]."""
        return self.pd_max * ndtr((power_db - self.sensitivity_db) / self.detection_spread_db)

    def log_likelihood(self, z_db: FloatArray | float, power_db: FloatArray) -> FloatArray:
        """log N(z; P, R) for a detected measurement z; broadcasts z against power."""
        r = self.noise_var
        d = z_db - power_db
        return -0.5 * (d * d / r + math.log(r) + _LOG_2PI)

    # -- noisy model ------------------------------------------------------------------------

    def measure(self, power_db: FloatArray, rng: np.random.Generator) -> FloatArray:
        """h(x, u) = P(x, u) + zeta, zeta ~ N(0, R); same shape as power_db."""
        return power_db + rng.normal(0.0, self.noise_std_db, size=np.shape(power_db))

    def detect(self, power_db: FloatArray, rng: np.random.Generator) -> NDArray[np.bool_]:
        """Bernoulli(pD(P)) draws: which pulses are detected; same shape as power_db."""
        pd = self.detection_probability(power_db)
        return rng.random(np.shape(pd)) < pd

    def distance_for_power_m(self, power_db: float, alt_m: float = 0.0) -> float:
        """Horizontal distance at which the (gain-free) power equals ``power_db``; 0 if none."""
        d3 = self.d0_m * 10.0 ** ((self.p0_db - power_db) / (10.0 * self.path_loss_exponent))
        return math.sqrt(max(d3 * d3 - alt_m * alt_m, 0.0))
