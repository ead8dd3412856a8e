"""Search area polygon."""

import numpy as np
import pytest

from mexgen_gcs.core.area import SearchArea


def test_rectangle_contains_and_distance():
    a = SearchArea.rectangle(-100, 100, 0, 50)
    pts = np.array([[0, 25], [150, 25], [-100.5, 10], [0, -20]])
    np.testing.assert_array_equal(a.contains(pts), [True, False, False, False])
    np.testing.assert_allclose(a.distance_outside_m(pts), [0, 50, 0.5, 20])
    assert a.bounds == (-100, 100, 0, 50)


def test_concave_polygon_and_sampling():
    # an L shape
    a = SearchArea(np.array([[0, 0], [100, 0], [100, 20], [20, 20], [20, 100], [0, 100.0]]))
    assert not a.contains(np.array([50.0, 50.0]))
    assert a.contains(np.array([10.0, 50.0]))
    pts = a.sample_uniform(5000, np.random.default_rng(0))
    assert pts.shape == (5000, 2) and a.contains(pts).all()


def test_degenerate_polygon_rejected():
    with pytest.raises(ValueError):
        SearchArea(np.array([[0, 0], [1, 1], [2, 2.0]]))
    with pytest.raises(ValueError):
        SearchArea.rectangle(10, 0, 0, 10)
