"""ENU <-> WGS84 round trips and heading helpers."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from mexgen_gcs.core.geo import LocalFrame, enu_to_heading_deg, heading_to_enu_unit, wrap_deg


@settings(max_examples=200, deadline=None)
@given(
    lat0=st.floats(-80, 80), lon0=st.floats(-179, 179), alt0=st.floats(-100, 3000),
    e=st.floats(-5000, 5000), n=st.floats(-5000, 5000), u=st.floats(-200, 500),
)
def test_enu_round_trip_to_millimetres(lat0, lon0, alt0, e, n, u):
    frame = LocalFrame(lat0, lon0, alt0)
    lat, lon, alt = frame.to_geodetic(e, n, u)
    e2, n2, u2 = frame.to_enu(lat, lon, alt)
    assert abs(e2 - e) < 1e-3 and abs(n2 - n) < 1e-3 and abs(u2 - u) < 1e-3


def test_enu_axes_point_east_and_north():
    frame = LocalFrame(-34.9212, 138.6011, 0.0)
    lat, lon, _ = frame.to_geodetic(0.0, 1000.0, 0.0)
    assert lat > -34.9212 and abs(lon - 138.6011) < 1e-9
    lat, lon, _ = frame.to_geodetic(1000.0, 0.0, 0.0)
    assert lon > 138.6011
    # about 1000 m of latitude is ~0.009 degrees
    e, n, _ = frame.to_enu(-34.9212 + 0.009, 138.6011, 0.0)
    assert abs(e) < 1e-6 and 990 < n < 1010


def test_vectorised_conversion():
    frame = LocalFrame(10.0, 20.0)
    e = np.linspace(-100, 100, 7)
    lat, lon, _alt = frame.to_geodetic(e, 0.0 * e, 0.0)
    assert lat.shape == (7,) and np.all(np.diff(lon) > 0)


def test_heading_helpers():
    np.testing.assert_allclose(heading_to_enu_unit(0.0), [0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(heading_to_enu_unit(90.0), [1.0, 0.0], atol=1e-12)
    assert enu_to_heading_deg(1.0, 1.0) == 45.0
    assert enu_to_heading_deg(-1.0, 0.0) == 270.0
    assert wrap_deg(190.0) == -170.0 and wrap_deg(-180.0) == 180.0
