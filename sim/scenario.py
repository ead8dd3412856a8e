"""The simulated world built from a mission file: airframe, parameters, tags, faults.

Frame: local ENU metres about the mission home. The mission schema (mexgen_gcs.config) is
the one source of truth; this module only translates it into the simulator's objects.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mexgen_gcs.config import Mission
from sim.faults import Fault, fault_from_config
from sim.iq import IqOptions
from sim.kinematics import Limits
from sim.radios import TagTruth

Address = tuple[str, int]


@dataclass(frozen=True)
class SimOptions:
    """Command-line choices (see ``python -m sim --help``)."""

    speedup: float = 1.0
    clock_rate_error: float = 0.0
    system_time: str = "sim"
    seed: int | None = None
    mavlink: Address = ("127.0.0.1", 14540)
    gcs: Address | None = None
    radio: Address = ("127.0.0.1", 14600)
    listen: Address = ("0.0.0.0", 0)
    truth_dir: Path | None = None
    sysid: int = 1
    extra_faults: tuple[Fault, ...] = field(default=())
    keep_running: bool = False
    radios: bool = True
    params: tuple[tuple[str, float], ...] = field(default=())
    """PX4 parameters set before the start (``--param NAME=VALUE``), over the defaults."""
    fence_latlon_deg: tuple[tuple[float, float], ...] = field(default=())
    """An inclusion fence already on board at the start (``--fence FILE``)."""
    radio_format: str = "wire-v1"
    """wire-v1, or mavlink-tunnel (TagTracker's TUNNEL PulseInfo_t, sim.tunnel_radio)."""
    iq: IqOptions | None = None
    """Serve the radio as IQ over rtl_tcp (``sim.iq``) instead of detection datagrams."""


def seed_of(mission: Mission, options: SimOptions) -> int:
    return mission.sim.seed if options.seed is None else options.seed


def airframe_limits(mission: Mission) -> Limits:
    """The paper's multirotor: 15 m/s, the mission's acceleration, 3/1.5 m/s climb/descent."""
    return Limits(max_speed_m_s=15.0, max_accel_m_s2=mission.flight.max_accel_m_s2)


def initial_params(mission: Mission, options: SimOptions | None = None) -> dict[str, float]:
    """PX4 SITL defaults except MPC_ACC_HOR, which follows the mission's max_accel_m_s2, and
    the ``--param`` values, which win."""
    return {"MPC_ACC_HOR": mission.flight.max_accel_m_s2,
            **dict(options.params if options is not None else ())}


def faults_of(mission: Mission, options: SimOptions) -> list[Fault]:
    return [fault_from_config(f) for f in mission.sim.faults] + list(options.extra_faults)


def build_tags(mission: Mission, rng: np.random.Generator) -> list[TagTruth]:
    """Every mission tag with its truth model and initial state (random where not given)."""
    area = mission.search_area()
    out: list[TagTruth] = []
    for spec in mission.tags:
        sim_tag = mission.sim_tag(spec.id)
        model = mission.sim_motion_model(spec.id, rng)
        if sim_tag.position_m is not None:
            xy = np.asarray([sim_tag.position_m], dtype=np.float64)
        else:
            xy = area.sample_uniform(1, rng).reshape(1, 2)
        state, mode = model.initial(xy, rng)
        if sim_tag.heading_deg is not None and sim_tag.motion not in ("static", "rw"):
            speed = float(np.hypot(state[0, 2], state[0, 3]))
            h = math.radians(sim_tag.heading_deg)
            state[0, 2], state[0, 3] = speed * math.sin(h), speed * math.cos(h)
        out.append(TagTruth(spec.id, int(spec.freq_hz), model, state, mode, sim_tag.motion))
    return out
