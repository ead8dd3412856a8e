"""What looks wrong in a mission that loads: human sentences for `mexgen-gcs check`.

Frame: ENU metres about home where a distance is computed.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from mexgen_gcs.config.mission import Mission

#: PX4 defaults the warnings refer to (observed on PX4 v1.17 SITL).
PX4_MPC_XY_VEL_MAX_M_S = 12.0
PX4_MPC_ACC_HOR_M_S2 = 3.0
MOVING_MOTIONS = ("cv", "ctra", "cv-ift")
"""Truth motion models in which a tag moves."""


def mission_warnings(mission: Mission) -> list[str]:
    """Human sentences about settings that load but may not do what the author expects."""
    out: list[str] = []
    flight, safety, receiver = mission.flight, mission.safety, mission.receiver
    if flight.speed_m_s > PX4_MPC_XY_VEL_MAX_M_S:
        out.append(f"flight.speed_m_s = {flight.speed_m_s:g}: PX4's default MPC_XY_VEL_MAX caps "
                   "horizontal speed at 12 m/s; the vehicle will fly slower than asked")
    if flight.max_accel_m_s2 > PX4_MPC_ACC_HOR_M_S2:
        out.append(f"flight.max_accel_m_s2 = {flight.max_accel_m_s2:g}: PX4's default "
                   "MPC_ACC_HOR caps horizontal acceleration at 3 m/s^2; turns will take longer "
                   "than the planner assumes")
    if flight.alt_m > 120.0:
        out.append(f"flight.alt_m = {flight.alt_m:g}: above 120 m, which most aviation rules "
                   "forbid without a permit")
    area = mission.search_area()
    outside_m = float(area.distance_outside_m(np.zeros(2)))
    if outside_m > 0.0:
        out.append(f"home is {outside_m:.0f} m outside the search area (allowed up to "
                   f"safety.home_max_distance_m = {safety.home_max_distance_m:g} m)")
    reach_m = mission.radio_model().distance_for_power_m(mission.radio.sensitivity_db,
                                                         flight.alt_m)
    if reach_m <= 0.0:
        out.append(f"at flight.alt_m = {flight.alt_m:g} m the radio model never reaches "
                   f"radio.sensitivity_db = {mission.radio.sensitivity_db:g} dB: no tag would "
                   "be detected")
    for tag in mission.tags:
        if not 30e6 <= tag.freq_hz <= 300e6:
            out.append(f"tag {tag.id}: freq_hz = {tag.freq_hz} is not a VHF frequency "
                       "(30-300 MHz); check it is in Hz")
    if mission.kind != "follow" and mission.follow is not None:
        out.append("the follow section is ignored because kind is 'localise'")
    if mission.follow is not None and mission.kind == "follow" and \
            mission.follow.duration_s > safety.max_mission_time_s:
        out.append(f"follow.duration_s = {mission.follow.duration_s:g} is longer than "
                   f"safety.max_mission_time_s = {safety.max_mission_time_s:g}: the mission "
                   "will return home first")
    if mission.planner.replan_interval_s > mission.planner.lookahead_s:
        out.append("planner.replan_interval_s is longer than planner.lookahead_s: the vehicle "
                   "keeps flying a plan past its horizon")
    if safety.radio_loss_timeout_s < receiver.heartbeat_timeout_s:
        out.append("safety.radio_loss_timeout_s is shorter than receiver.heartbeat_timeout_s: "
                   "the receiver counts as lost before it counts as silent")
    host = receiver.listen.removeprefix("udp://").rpartition(":")[0].strip("[]")
    if not receiver.allowed_sources and host not in ("127.0.0.1", "::1", "localhost"):
        out.append(f"receiver.allowed_sources is empty and {receiver.listen} is reachable from "
                   "other machines: detections from any address are accepted")
    out += _sim_warnings(mission)
    return out


def _sim_warnings(mission: Mission) -> list[str]:
    out: list[str] = []
    listed = {t.id for t in mission.sim.tags}
    missing = [tid for tid in mission.tag_ids if tid not in listed]
    if mission.sim.tags and missing:
        out.append(f"sim: tags {', '.join(missing)} have no sim.tags entry; the simulator "
                   "places them, static, at random")
    f = mission.filter
    for sim_tag in mission.sim.tags:
        if sim_tag.motion in MOVING_MOTIONS and f.motion in ("static", "rw"):
            out.append(f"sim: tag {sim_tag.id} moves ({sim_tag.motion}) but filter.motion is "
                       f"{f.motion}: the filter has no velocity to follow it with")
        if sim_tag.motion in MOVING_MOTIONS and sim_tag.speed_m_s[1] > f.speed_max_m_s:
            out.append(f"sim: tag {sim_tag.id} moves up to {sim_tag.speed_m_s[1]:g} m/s, faster "
                       f"than filter.speed_max_m_s = {f.speed_max_m_s:g}")
    return out
