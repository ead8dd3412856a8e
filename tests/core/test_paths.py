"""Action paths: compass convention, acceleration limit, pruning tests."""

import math

import numpy as np
import pytest

from mexgen_gcs.core.area import SearchArea
from mexgen_gcs.core.paths import (
    PRUNE_SUBSTEPS,
    action_headings_rad,
    compass_bearing_rad,
    fine_times_s,
    inside_test,
    leaves_area,
    vehicle_paths,
)


def test_eight_headings_from_north_clockwise():
    np.testing.assert_allclose(np.degrees(action_headings_rad(8)), np.arange(8) * 45.0)
    with pytest.raises(ValueError):
        action_headings_rad(0)


def test_compass_bearing():
    assert compass_bearing_rad([0, 0], [0, 10]) == pytest.approx(0.0)
    assert compass_bearing_rad([0, 0], [10, 0]) == pytest.approx(math.pi / 2)
    assert compass_bearing_rad([0, 0], [-10, -10]) == pytest.approx(math.radians(225))
    assert compass_bearing_rad([3, 3], [3, 3]) == 0.0


def test_from_rest_accelerates_then_holds_speed():
    h = np.radians([90.0])  # east
    t = np.array([1.0, 2.0, 2.5, 4.0])
    p = vehicle_paths(np.array([5.0, 7.0, 50.0]), np.zeros(2), h, 10.0, 4.0, t)
    assert p.shape == (4, 1, 2)
    # 0.5 a t^2 until t = 2.5 s (10 m/s at 4 m/s^2), then 10 m/s
    expected_east = [2.0, 8.0, 12.5, 12.5 + 15.0]
    np.testing.assert_allclose(p[:, 0, 0], 5.0 + np.array(expected_east))
    np.testing.assert_allclose(p[:, 0, 1], 7.0)


def test_already_at_speed_flies_straight_and_turns_continuously():
    v0 = np.array([0.0, 10.0])  # north at speed
    h = np.radians([0.0, 180.0])
    t = np.linspace(0.1, 10.0, 100)
    p = vehicle_paths(np.zeros(2), v0, h, 10.0, 4.0, t)
    np.testing.assert_allclose(p[:, 0, 1], 10.0 * t)  # holding north
    # reversing: decelerates through zero after 2.5 s, never teleports
    step = np.linalg.norm(np.diff(p[:, 1], axis=0), axis=-1)
    assert np.all(step <= 10.0 * 0.1 + 1e-9)
    assert p[24, 1, 1] == pytest.approx(12.5, abs=0.2)  # furthest north at t = 2.5 s
    assert p[-1, 1, 1] < 0.0


def test_infinite_acceleration_and_bad_acceleration():
    p = vehicle_paths(np.zeros(2), np.zeros(2), np.radians([45.0]), 10.0, math.inf,
                      np.array([1.0]))
    np.testing.assert_allclose(p[0, 0], [10 / math.sqrt(2), 10 / math.sqrt(2)])
    with pytest.raises(ValueError):
        vehicle_paths(np.zeros(2), np.zeros(2), np.zeros(1), 10.0, 0.0, np.ones(1))


def test_fine_times_contain_the_step_times():
    t = fine_times_s(20.0, 1.0)
    assert t.size == 20 * PRUNE_SUBSTEPS
    np.testing.assert_allclose(t[PRUNE_SUBSTEPS - 1 :: PRUNE_SUBSTEPS], np.arange(1, 21))


@pytest.mark.parametrize(
    "vertices",
    [
        [[0, 0], [10, 0], [10, 5], [0, 5]],  # counter-clockwise rectangle
        [[0, 0], [0, 5], [10, 5], [10, 0]],  # clockwise
        [[0, 0], [10, -2], [12, 8], [3, 9]],  # convex quadrilateral
        [[0, 0], [10, 0], [10, 6], [5, 2], [0, 6]],  # concave: falls back to even-odd
    ],
)
def test_inside_test_agrees_with_area_contains(vertices):
    area = SearchArea(np.array(vertices, dtype=float))
    inside = inside_test(area)
    pts = np.random.default_rng(0).uniform(-3, 14, (20_000, 2))
    agree = inside(pts) == area.contains(pts)
    # they may differ only on the boundary itself (measure zero)
    assert agree.all()


def test_leaves_area_flags_only_paths_that_exit():
    area = SearchArea.rectangle(-100, 100, -100, 100)
    h = action_headings_rad(8)
    pts = vehicle_paths(np.array([0.0, 80.0]), np.zeros(2), h, 10.0, 4.0, fine_times_s(5.0, 1.0))
    out = leaves_area(inside_test(area), pts)
    # 80 m north of centre, 20 m from the north edge: N, NE, NW leave within 5 s
    np.testing.assert_array_equal(out, [True, True, False, False, False, False, False, True])
