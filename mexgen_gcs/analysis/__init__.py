"""Post-flight analysis of flight logs: reports and plots, comparison of several flights,
path-loss calibration, GIS exports, and planner-in-the-loop replay (see docs/architecture.md).

Frame: local ENU metres about the mission home throughout, WGS84 for lat/lon outputs.
Entry points: ``mexgen-gcs analyze`` and ``mexgen-gcs replay`` (``analysis.cli``); the
library API below is what they use.
"""

from mexgen_gcs.analysis.calibration import PathLossFit, calibrate, fit_path_loss
from mexgen_gcs.analysis.flightdata import FlightData, load_flight
from mexgen_gcs.analysis.summary import FlightSummary, summarise
from mexgen_gcs.analysis.truth import Truth, load_truth

__all__ = [
    "FlightData",
    "FlightSummary",
    "PathLossFit",
    "Truth",
    "calibrate",
    "fit_path_loss",
    "load_flight",
    "load_truth",
    "summarise",
]
