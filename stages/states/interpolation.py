"""Key-frame interpolation of one object's state over source frame indices.

- ``linear``: piecewise linear, as the LiveScene reference code does;
- ``pchip``: monotone piecewise cubic (SciPy's PchipInterpolator): smooth, yet
  never overshoots the neighbouring key values, so a door that slams shut
  between two key frames stays inside [closed, open];
- ``step``: holds each key value until the next key frame (zero-order hold);
- ``nearest``: the value of the nearest key frame (ties go to the earlier one).

Every method holds the first / last key value outside the annotated range
(no extrapolation).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from scipy.interpolate import PchipInterpolator

Method = Literal["linear", "pchip", "step", "nearest"]
METHODS: tuple[str, ...] = ("linear", "pchip", "step", "nearest")


def interpolate(key_x: np.ndarray, key_y: np.ndarray, x: np.ndarray, method: str) -> np.ndarray:
    """Values at ``x`` from key frames ``(key_x, key_y)``; ``key_x`` strictly increasing."""
    key_x = np.asarray(key_x, dtype=np.float64)
    key_y = np.asarray(key_y, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    if key_x.ndim != 1 or key_x.shape != key_y.shape or key_x.size == 0:
        raise ValueError("key frames must be two 1-D arrays of the same, non-zero length")
    if key_x.size > 1 and not (np.diff(key_x) > 0).all():
        raise ValueError("key frame positions must be strictly increasing")
    if method not in METHODS:
        raise ValueError(f"unknown interpolation method {method!r}; use one of {METHODS}")
    if key_x.size == 1:
        return np.full(x.shape, key_y[0])
    held = np.clip(x, key_x[0], key_x[-1])
    if method == "linear":
        return np.interp(held, key_x, key_y)
    if method == "pchip":
        # SciPy's harmonic-mean slopes divide by secants; a subnormal secant overflows to a zero slope, which is
        # the right limit, so the warning carries no information
        with np.errstate(over="ignore", divide="ignore"):
            out = PchipInterpolator(key_x, key_y, extrapolate=False)(held)
        # exact at the knots (the cubic's rounding could otherwise leave 1 ulp off a key value)
        at_knot = np.searchsorted(key_x, held)
        hit = (at_knot < key_x.size) & (key_x[np.minimum(at_knot, key_x.size - 1)] == held)
        out[hit] = key_y[at_knot[hit]]
        return out
    if method == "step":
        return key_y[np.searchsorted(key_x, held, side="right") - 1]
    # nearest: compare distances to the key frames either side
    right = np.clip(np.searchsorted(key_x, held, side="left"), 1, key_x.size - 1)
    left = right - 1
    take_right = (key_x[right] - held) < (held - key_x[left])
    return np.where(take_right, key_y[right], key_y[left])


def leave_one_out(key_x: np.ndarray, key_y: np.ndarray, method: str) -> np.ndarray:
    """Absolute error at each interior key frame when it is predicted from all the others.

    The end key frames are left out of the score: predicting them would be
    extrapolation, which every method replaces by holding the nearest value.
    """
    key_x = np.asarray(key_x, dtype=np.float64)
    key_y = np.asarray(key_y, dtype=np.float64)
    errors = []
    for i in range(1, key_x.size - 1):
        keep = np.arange(key_x.size) != i
        pred = interpolate(key_x[keep], key_y[keep], key_x[i:i + 1], method)[0]
        errors.append(abs(pred - key_y[i]))
    return np.asarray(errors, dtype=np.float64)
