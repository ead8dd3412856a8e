"""The in-place power grid is the radio model's power_db, evaluated without allocations."""

import numpy as np
import pytest

from mexgen_gcs.core.power_grid import power_grid
from mexgen_gcs.core.radio import RadioModel
from mexgen_gcs.core.workspace import Workspace


@pytest.mark.parametrize(
    "radio",
    [
        RadioModel(),
        RadioModel(front_back_db=0.0),
        RadioModel(d0_m=10.0, p0_db=-20.0, path_loss_exponent=2.7, front_back_db=6.0),
        RadioModel(min_distance_m=5.0),
    ],
)
def test_power_grid_equals_radio_power_db(radio):
    rng = np.random.default_rng(0)
    xy = rng.uniform(-800, 800, (3, 1, 1, 257, 2)).astype(np.float32)
    xy[0, 0, 0, :3] = 0.0  # tags right under a receiver at the origin
    rx = np.zeros((3, 5, 1, 1, 3), dtype=np.float32)
    rx[..., :2] = rng.uniform(-300, 300, (3, 5, 1, 1, 2))
    rx[0, 0, 0, 0] = (0.0, 0.0, 0.0)  # ... and at zero height: the distance clamp
    rx[1:, ..., 2] = 50.0
    yaw = rng.uniform(0, 2 * np.pi, (1, 5, 1, 1)).astype(np.float32)
    expected = radio.power_db(xy.astype(np.float64), rx.astype(np.float64),
                              yaw.astype(np.float64))
    ws = Workspace()
    shape = expected.shape
    out = ws.get("out", shape)
    got = power_grid(radio, xy, rx, yaw, out, [ws.get(f"s{i}", shape) for i in range(3)])
    assert got is out and got.dtype == np.float32
    np.testing.assert_allclose(got, expected, atol=1e-4)


def test_workspace_reuses_and_grows_buffers():
    ws = Workspace()
    a = ws.get("x", (4, 5))
    b = ws.get("x", (2, 3))
    assert np.shares_memory(a, b) and b.flags.c_contiguous
    c = ws.get("x", (10, 10))
    assert c.shape == (10, 10) and ws.nbytes == 400
    assert ws.get("i", (3,), np.int32).dtype == np.int32
