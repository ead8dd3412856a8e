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


def _ccw_convex(poly: np.ndarray) -> bool:
    a, b, c = poly, np.roll(poly, -1, axis=0), np.roll(poly, -2, axis=0)
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - b[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - b[:, 0])
    return bool(np.all(cross > 0))


def _dilation_samples(area: SearchArea, margin: float, n: int = 4000) -> np.ndarray:
    """Points at distance <= margin from the area (on and near the boundary, where it is hard)."""
    rng = np.random.default_rng(5)
    v = area.vertices_m
    a, b = v, np.roll(v, -1, axis=0)
    i = rng.integers(0, len(v), n)
    t = rng.uniform(0, 1, n)[:, None]
    on_edge = a[i] + t * (b[i] - a[i])
    ang = rng.uniform(0, 2 * np.pi, n)
    r = margin * np.sqrt(rng.uniform(0.8, 1.0, n))
    return on_edge + r[:, None] * np.column_stack([np.cos(ang), np.sin(ang)])


@pytest.mark.parametrize("margin", [0.0, 1.0, 50.0, 400.0])
@pytest.mark.parametrize("vertices", [
    [[-500, -500], [500, -500], [500, 500], [-500, 500]],       # the demo's square
    [[0, 0], [100, 0], [100, 20], [20, 20], [20, 100], [0, 100]],  # concave L
    [[0, 0], [1000, 0], [1000, 60]],                            # a thin sliver (sharp corners)
    [[0, 0], [300, -40], [600, 0], [620, 300], [300, 380], [-30, 250]],  # irregular hexagon
])
def test_fence_contains_the_area_dilated_by_the_margin(margin, vertices):
    area = SearchArea(np.array(vertices, dtype=float))
    fence_v = area.fence_polygon(margin)
    assert _ccw_convex(fence_v)
    fence = SearchArea(fence_v)
    pts = _dilation_samples(area, margin) if margin > 0 else area.vertices_m
    assert area.distance_outside_m(pts).max() <= margin + 1e-6  # the samples are in range
    assert fence.distance_outside_m(pts).max() <= 1e-6
    # and it is not much bigger: every fence vertex within sqrt(2) * margin of the area
    assert area.distance_outside_m(fence_v).max() <= np.sqrt(2) * margin + 1e-6


def test_fence_holds_extra_points_and_paths_between_them():
    area = SearchArea.rectangle(0, 400, 0, 400)
    home = np.array([[-300.0, -250.0]])
    fence = SearchArea(area.fence_polygon(50.0, home))
    assert fence.contains(home[0])
    # a straight return from the far corner to home stays inside, 50 m from the fence
    path = np.linspace([400.0, 400.0], home[0], 200)
    assert fence.contains(path).all()
    edges_from_home = fence.distance_outside_m(home[0] + np.array([[-49.0, 0.0], [0, -49.0]]))
    assert (edges_from_home == 0).all()


def test_fence_margin_rejects_bad_values():
    area = SearchArea.rectangle(0, 10, 0, 10)
    for bad in (-1.0, np.nan, np.inf):
        with pytest.raises(ValueError):
            area.fence_polygon(bad)


def test_distance_outside_a_rectangle_everywhere():
    """The compiled even-odd test and segment distances against the rectangle's closed form,
    on a grid straddling the boundary, any leading shape."""
    area = SearchArea.rectangle(-100.0, 300.0, -50.0, 50.0)
    # no point exactly on an edge (those may go either way)
    xs, ys = np.meshgrid(np.linspace(-400.5, 599.5, 101), np.linspace(-201.0, 199.0, 41))
    pts = np.stack([xs, ys], axis=-1)  # (41, 101, 2)
    dx = np.maximum(np.maximum(-100.0 - xs, xs - 300.0), 0.0)
    dy = np.maximum(np.maximum(-50.0 - ys, ys - 50.0), 0.0)
    strictly_in = (np.abs(xs - 100.0) < 200.0) & (np.abs(ys) < 50.0)
    np.testing.assert_array_equal(area.contains(pts), strictly_in)
    np.testing.assert_allclose(area.distance_outside_m(pts), np.hypot(dx, dy), atol=1e-9)
    assert area.contains(np.array([0.0, 0.0])).shape == ()
