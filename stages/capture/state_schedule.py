"""Object states over time: key (time, state) pairs interpolated to every frame."""

from __future__ import annotations

import numpy as np

from .spec import CaptureSpec, ScheduleSpec


def smoothstep(x: np.ndarray) -> np.ndarray:
    """Ease in and out: zero speed at both ends, as a hand opening a door."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def evaluate_schedule(schedule: ScheduleSpec, times: np.ndarray) -> np.ndarray:
    """State in [0, 1] at each time fraction; held constant before the first and after the last key."""
    keys = np.asarray(schedule.keys, dtype=np.float64)
    kt, kv = keys[:, 0], keys[:, 1]
    times = np.asarray(times, dtype=np.float64)
    if len(kt) == 1:
        return np.full_like(times, kv[0])
    # segment j spans keys j..j+1; "right" makes a step land exactly on its key time
    j = np.clip(np.searchsorted(kt, times, side="right") - 1, 0, len(kt) - 2)
    t0, t1, v0, v1 = kt[j], kt[j + 1], kv[j], kv[j + 1]
    span = np.where(t1 > t0, t1 - t0, 1.0)
    x = np.clip((times - t0) / span, 0.0, 1.0)
    x = np.where(t1 > t0, x, 1.0)  # two keys at one time: a jump
    if schedule.interpolation == "step":
        x = (times >= t1).astype(np.float64)
    elif schedule.interpolation == "smooth":
        x = smoothstep(x)
    out = v0 + (v1 - v0) * x
    out = np.where(times < kt[0], kv[0], out)
    return np.where(times >= kt[-1], kv[-1], out)


def time_fractions(spec: CaptureSpec, positions: np.ndarray) -> np.ndarray:
    """Time fraction at frame positions (frame index, fractional between frames): 0 at the first frame, 1 at the
    last; outside them for a sub-frame time before the first or after the last frame (schedules hold there).

    The arithmetic of ``np.linspace(0, 1, n)`` (index x step, the last exactly 1), so whole frames keep the bits
    their states had when this was ``linspace``."""
    positions = np.asarray(positions, dtype=np.float64)
    n = spec.video.n_frames
    if n <= 1:
        return np.zeros_like(positions)
    out = positions * (1.0 / (n - 1))
    return np.where(positions == n - 1, 1.0, out)


def frame_times(spec: CaptureSpec) -> np.ndarray:
    """Time fraction of each frame: 0 at the first, 1 at the last."""
    return time_fractions(spec, np.arange(spec.video.n_frames))


def states_at(spec: CaptureSpec, positions: np.ndarray) -> np.ndarray:
    """``[len(positions), n_objects]`` states in [0, 1] at frame positions, columns in spec (mapping id) order."""
    t = time_fractions(spec, positions)
    if not spec.objects:
        return np.zeros((len(t), 0))
    return np.stack([evaluate_schedule(o.schedule, t) for o in spec.objects], axis=1)


def state_table(spec: CaptureSpec) -> np.ndarray:
    """``[n_frames, n_objects]`` dense states in [0, 1], columns in spec (mapping id) order."""
    return states_at(spec, np.arange(spec.video.n_frames))
