"""State schedules: key times are fractions of the capture, values interpolated as docs/captures.md says."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from stages.capture import load_spec, spec_from_dict
from stages.capture.spec import ScheduleSpec
from stages.capture.state_schedule import evaluate_schedule, frame_times, state_table, states_at

PRESETS = Path(__file__).resolve().parents[2] / "config" / "captures"


def test_frame_times_run_from_the_first_to_the_last_frame():
    np.testing.assert_allclose(frame_times(load_spec_frames(5)), [0.0, 0.25, 0.5, 0.75, 1.0])
    np.testing.assert_allclose(frame_times(load_spec_frames(1)), [0.0])


def test_frame_times_keep_linspaces_bits():
    """States at whole frames are those of the frame times np.linspace(0, 1, n) gave before states_at existed."""
    spec = load_spec_frames(2)
    for n in range(2, 300):
        spec.video.n_frames = n
        assert np.array_equal(frame_times(spec), np.linspace(0.0, 1.0, n)), n


def test_states_between_frames_follow_the_schedule_and_hold_outside_the_capture():
    spec = load_spec(PRESETS / "tiny.yaml")  # 30 frames; the drawer opens (smooth) from t = 0.4 to 0.7
    table = state_table(spec)
    assert np.array_equal(states_at(spec, np.arange(30)), table)
    between = states_at(spec, np.array([14.5]))[0]  # t = 0.5: a third of the way, smoothstep(1/3) = 7/27
    assert between[1] == pytest.approx(7 / 27)
    assert np.array_equal(states_at(spec, np.array([-0.4, 29.4])), table[[0, -1]])


def load_spec_frames(n: int):
    return spec_from_dict({"name": "t", "video": {"n_frames": n}})


@pytest.mark.parametrize(
    ("interpolation", "expected"),
    [
        # a quarter of the way through the segment 0.2 .. 0.6 (t = 0.3), held outside the keys
        ("linear", [0.2, 0.2, 0.2 + 0.25 * 0.6, 0.5, 0.8, 0.8]),
        ("smooth", [0.2, 0.2, 0.2 + 0.15625 * 0.6, 0.5, 0.8, 0.8]),  # 3 x^2 - 2 x^3 at x = 1/4
        ("step", [0.2, 0.2, 0.2, 0.8, 0.8, 0.8]),
    ],
)
def test_interpolations_between_two_keys(interpolation, expected):
    schedule = ScheduleSpec(keys=[[0.2, 0.2], [0.6, 0.8]], interpolation=interpolation)
    times = np.array([0.0, 0.2, 0.3, 0.4, 0.6, 1.0])
    if interpolation == "step":  # holds the first key's value until the next key's time, then jumps
        times = np.array([0.0, 0.2, 0.3, 0.6, 0.7, 1.0])
    np.testing.assert_allclose(evaluate_schedule(schedule, times), expected, atol=1e-12)


@pytest.mark.parametrize("interpolation", ["linear", "smooth", "step"])
def test_two_keys_at_one_time_jump_and_land_on_the_later_value(interpolation):
    keys = [[0.0, 0.0], [0.5, 0.0], [0.5, 1.0], [1.0, 1.0]]
    spec = spec_from_dict(
        {
            "name": "t",
            "objects": [
                {
                    "name": "box",
                    "kind": "drawer",
                    "position": [0, 0, 0],
                    "size": [0.5, 0.5, 0.5],
                    "schedule": {"keys": keys, "interpolation": interpolation},
                }
            ],
        }
    )  # equal key times are allowed
    got = evaluate_schedule(spec.objects[0].schedule, np.array([0.25, 0.4999, 0.5, 0.75]))
    np.testing.assert_allclose(got, [0.0, 0.0, 1.0, 1.0])


def test_the_stiff_preset_slams_between_the_frames_its_doc_names():
    """docs/captures.md: the door opens between frames 23 and 24 and closes between 55 and 56 (of 80)."""
    spec = load_spec(PRESETS / "stiff.yaml")
    door = state_table(spec)[:, 0]
    expected = np.zeros(80)
    expected[24:56] = 1.0
    np.testing.assert_array_equal(door, expected)


def test_state_table_columns_follow_the_spec_order(small_spec):
    spec = small_spec(n_frames=3)  # times 0, 0.5, 1
    table = state_table(spec)
    # cabinet: keys (0.15, 0) (0.5, 1) (0.85, 0); drawer: (0.4, 0) (0.7, 1), smooth: x = 1/3 -> 7/27 at t = 0.5
    np.testing.assert_allclose(table, [[0.0, 0.0], [1.0, 7.0 / 27.0], [0.0, 1.0]], atol=1e-12)
