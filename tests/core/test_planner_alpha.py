"""Every Renyi order the configuration accepts plans: alpha above 1 (where the exact sum
meets the zero-weight padding of a particle count that is not a multiple of 16) as well as
below."""


import numpy as np
import pytest

from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.motion import make_motion_model
from mexgen_gcs.core.planner import PlannerConfig, TagBelief, VehicleState, plan
from mexgen_gcs.core.radio import RadioModel

AREA = SearchArea.rectangle(-1000, 1000, -1000, 1000)
HOVER = VehicleState(np.array([0.0, 0.0, 50.0]), np.zeros(2), 0.0)
SHORT_RANGE = RadioModel(sensitivity_db=-45.0)

@pytest.mark.parametrize("n_particles", [1000, 333])  # neither a multiple of 16
@pytest.mark.parametrize("method", ["pim", "mexgen", "mc"])
@pytest.mark.parametrize("alpha", [0.5, 2.0, 5.0])
def test_any_alpha_plans_towards_the_tag(alpha, method, n_particles):
    rng = np.random.default_rng(0)
    model = make_motion_model("static")
    states, modes = model.initial(rng.normal([350.0, 0.0], 40.0, (n_particles, 2)), rng)
    belief = TagBelief("T1", states, modes, model)
    config = PlannerConfig(method=method, alpha=alpha, samples=64, mc_rollouts=8)
    result = plan([belief], HOVER, AREA, SHORT_RANGE, config, np.random.default_rng(1))
    assert np.all(np.isfinite(result.rewards)) and np.all(result.rewards >= 0.0)
    assert result.rewards.max() > 0.0
    if method != "mc":  # MC is noisy by design (tests/core/test_planner.py)
        assert result.heading_deg == 90.0, result.rewards
