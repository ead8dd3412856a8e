"""Mission configuration: the typed schema of a mission file and its loader.

`load_mission(path)` returns a validated, frozen `Mission` or raises `ConfigError` naming the
file, line, key path, what was found and what is expected. See missions/README.md.
"""

from mexgen_gcs.config.checks import mission_warnings
from mexgen_gcs.config.describe import describe, dump_resolved
from mexgen_gcs.config.loader import MissionFileError, Problem, load_mission, parse_mission
from mexgen_gcs.config.mission import Mission
from mexgen_gcs.config.schema import CLASSIC_ESTIMATOR
from mexgen_gcs.config.urls import UdpAddress, parse_udp_url

__all__ = [
    "CLASSIC_ESTIMATOR",
    "Mission",
    "MissionFileError",
    "Problem",
    "UdpAddress",
    "describe",
    "dump_resolved",
    "load_mission",
    "mission_warnings",
    "parse_mission",
    "parse_udp_url",
]
