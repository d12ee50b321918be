"""Properties of the interpolants, for any key frames hypothesis can think of."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stages.states import METHODS, interpolate, leave_one_out

EPS = 1e-9


@st.composite
def key_frames(draw, monotone: bool = False):
    n = draw(st.integers(2, 9))
    xs = sorted(draw(st.lists(st.integers(0, 300), min_size=n, max_size=n, unique=True)))
    ys = draw(st.lists(st.floats(0, 1, allow_nan=False, allow_infinity=False), min_size=n, max_size=n))
    if monotone:
        ys = sorted(ys, reverse=draw(st.booleans()))
    return np.array(xs, dtype=float), np.array(ys)


def dense(key_x: np.ndarray) -> np.ndarray:
    return np.arange(key_x[0] - 5, key_x[-1] + 6, dtype=float)


@pytest.mark.parametrize("method", ["linear", "pchip"])
@settings(max_examples=60, deadline=None)
@given(keys=key_frames())
def test_passes_through_every_key_frame(method, keys):
    key_x, key_y = keys
    np.testing.assert_allclose(interpolate(key_x, key_y, key_x, method), key_y, atol=EPS, rtol=0)


@pytest.mark.parametrize("method", ["linear", "pchip"])
@settings(max_examples=60, deadline=None)
@given(keys=key_frames())
def test_stays_within_neighbouring_key_frames_and_monotone_between_them(method, keys):
    key_x, key_y = keys
    x = dense(key_x)
    y = interpolate(key_x, key_y, x, method)
    for k in range(len(key_x) - 1):
        inside = (x >= key_x[k]) & (x <= key_x[k + 1])
        seg = y[inside]
        lo, hi = sorted((key_y[k], key_y[k + 1]))
        assert seg.min() >= lo - EPS and seg.max() <= hi + EPS
        steps = np.diff(seg) * np.sign(key_y[k + 1] - key_y[k])
        assert (steps >= -EPS).all()  # moves only in the direction of its two key frames
    # holds outside the annotated range
    assert np.allclose(y[x < key_x[0]], key_y[0]) and np.allclose(y[x > key_x[-1]], key_y[-1])


@pytest.mark.parametrize("method", ["linear", "pchip"])
@settings(max_examples=60, deadline=None)
@given(keys=key_frames(monotone=True))
def test_monotone_key_frames_give_a_monotone_interpolant(method, keys):
    key_x, key_y = keys
    y = interpolate(key_x, key_y, dense(key_x), method)
    direction = np.sign(key_y[-1] - key_y[0]) or 1.0
    assert (np.diff(y) * direction >= -EPS).all()


@pytest.mark.parametrize("method", METHODS)
def test_step_from_0_at_10_to_1_at_11_stays_in_unit_range(method):
    for key_x, key_y in [([10, 11], [0, 1]), ([0, 10, 11, 30], [0, 0, 1, 1]), ([0, 10, 11, 12, 40], [0, 0, 1, 0, 0])]:
        y = interpolate(np.array(key_x, float), np.array(key_y, float), np.arange(0, 50, 0.25), method)
        assert y.min() >= 0.0 and y.max() <= 1.0


def test_pchip_does_not_overshoot_where_a_cubic_spline_would():
    from scipy.interpolate import CubicSpline

    key_x, key_y = np.array([0.0, 10, 11, 30]), np.array([0.0, 0, 1, 1])
    x = np.linspace(0, 30, 301)
    assert CubicSpline(key_x, key_y)(x).max() > 1.05  # the spline overshoots a slammed door
    assert interpolate(key_x, key_y, x, "pchip").max() <= 1.0


def test_step_holds_and_nearest_picks_the_closer_key_frame():
    key_x, key_y = np.array([0.0, 10.0]), np.array([0.2, 0.8])
    x = np.array([-3, 0, 4, 5, 6, 10, 12], float)
    np.testing.assert_array_equal(interpolate(key_x, key_y, x, "step"), [0.2, 0.2, 0.2, 0.2, 0.2, 0.8, 0.8])
    np.testing.assert_array_equal(interpolate(key_x, key_y, x, "nearest"), [0.2, 0.2, 0.2, 0.2, 0.8, 0.8, 0.8])


def test_single_key_frame_is_held_everywhere():
    for method in METHODS:
        np.testing.assert_array_equal(interpolate(np.array([5.0]), np.array([0.3]), np.arange(10.0), method), 0.3)


def test_leave_one_out_is_zero_for_linear_data_and_scores_interior_frames():
    key_x = np.array([0.0, 5, 10, 20])
    key_y = key_x / 20
    err = leave_one_out(key_x, key_y, "linear")
    assert err.shape == (2,) and np.allclose(err, 0)
    assert leave_one_out(key_x, key_y, "step").max() > 0.2
