"""The command line spells some choices itself (so --help stays light): they must be the ones
the modules define."""

from mexgen_gcs import cli
from mexgen_gcs.core.reality import PROFILES
from mexgen_gcs.experiments.scenario import ESTIMATORS, MODELS


def test_experiment_choices_match_their_definitions() -> None:
    assert cli.EXPERIMENT_MODELS == MODELS
    assert tuple(PROFILES) == cli.REALITIES
    assert cli.ESTIMATORS == ESTIMATORS
