"""`livescene states` on inputs where the expected answer differs from a plausible mistake: frames whose
source indices are not their row numbers, ranges given for every object or over a format's convention, key
values just past a range's end, key-frame error by hand, frames.csv out of order."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from state_files import write_frames_csv, write_text

from stages.states import StateError, StatesConfig, compute_states, interpolate
from stages.states.frame_table import read_frame_table


def _states(tmp: Path, keys: Path, indices: list[int], **kw) -> tuple[dict, pd.DataFrame]:
    frames = write_frames_csv(tmp / "frames.csv", indices)
    summary = compute_states(StatesConfig(key_frames=keys, frames=frames, out=tmp / "out", **kw))
    return summary, pd.read_csv(tmp / "out" / "states.csv")


def _object(table: pd.DataFrame, name: str) -> pd.DataFrame:
    return table[table.object == name].set_index("source_index")


def test_interpolation_runs_over_source_indices_not_row_numbers(tmp_path):
    """Every other source frame extracted (0, 2, ..., 20): source 10 is halfway between keys 0 and 20."""
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,0\n20,door,1\n")
    _, table = _states(tmp_path, keys, list(range(0, 21, 2)), method="linear")
    door = _object(table, "door")
    assert list(door.index) == list(range(0, 21, 2))
    assert door.loc[10, "value"] == pytest.approx(0.5)  # row 5
    assert door.loc[20, "value"] == pytest.approx(1.0)  # row 10
    assert door.loc[4, "value"] == pytest.approx(0.2)
    # the key-frame flag follows the source index too: sources 0 and 20, i.e. rows 0 and 10
    assert door.index[door["is_key_frame"]].tolist() == [0, 20]


def test_the_method_with_the_smallest_leave_one_out_error_is_suggested(tmp_path):
    """A door slammed shut between frames 10 and 11, predicted at each interior key from the other three:
    step 0 and 1 (MAE 0.5); linear 10/11 and 1 - 1/20; nearest 1 and 1; pchip, monotone from 0 to 1 with a
    flat end, just under 1 both times. Step is the best, nearest the worst."""
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,0\n10,door,0\n11,door,1\n30,door,1\n")
    summary, _ = _states(tmp_path, keys, list(range(31)))
    loo = summary["leave_one_out"]["door"]
    assert loo["step"]["mae"] == pytest.approx(0.5) and loo["step"]["n"] == 2
    assert loo["linear"]["mae"] == pytest.approx((10 / 11 + 0.95) / 2)
    assert loo["nearest"]["mae"] == pytest.approx(1.0)
    assert 0.9 < loo["pchip"]["mae"] < 1.0
    assert summary["suggested_method"]["door"] == "step"


def test_a_star_range_applies_to_every_object(tmp_path):
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,0\n10,door,45\n0,lid,0\n10,lid,90\n")
    summary, table = _states(tmp_path, keys, list(range(11)), ranges={"*": (0.0, 90.0)})
    assert _object(table, "door").loc[10, "value"] == pytest.approx(0.5)  # 45 of [0, 90], not min-max's 1
    assert _object(table, "lid").loc[10, "value"] == pytest.approx(1.0)
    assert summary["ranges"]["door"] == {"lo": 0.0, "hi": 90.0, "source": "--range"}


def test_a_user_range_wins_over_the_conerf_convention(tmp_path):
    write_text(tmp_path / "mapping.yml", "0: left eye\n")
    keys = write_text(tmp_path / "annotations.yml", """
- class: 0
  frame: 0
  value: -1
- class: 0
  frame: 20
  value: 1
""")
    summary, table = _states(tmp_path, keys, list(range(21)), ranges={"left eye": (-2.0, 2.0)})
    eye = _object(table, "left eye")
    assert eye.loc[0, "value"] == pytest.approx(0.25)  # (-1 - -2) / 4
    assert eye.loc[20, "value"] == pytest.approx(0.75)
    assert summary["ranges"]["left eye"]["source"] == "--range"


def test_the_key_span_is_measured_in_the_normalised_unit(tmp_path):
    """4.5 degrees of a 0-90 door: a span of 0.05 of [0, 1], under STILL_SPAN, so the door is named as still."""
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,0\n10,door,4.5\n")
    summary, _ = _states(tmp_path, keys, list(range(11)), ranges={"door": (0.0, 90.0)})
    assert summary["key_span"]["door"] == pytest.approx(0.05)
    assert summary["still"] == ["door"]


def test_a_range_includes_its_ends_and_nothing_past_them(tmp_path):
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,0\n10,door,90.0\n")
    _, table = _states(tmp_path, keys, list(range(11)), ranges={"door": (0.0, 90.0)})
    assert _object(table, "door").loc[10, "value"] == 1.0
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,0\n10,door,90.5\n")
    with pytest.raises(StateError, match=r"row 3: value 90\.5 of 'door' lies outside the range \[0\.0, 90\.0\]"):
        _states(tmp_path, keys, list(range(11)), ranges={"door": (0.0, 90.0)})


def test_frames_csv_out_of_order_is_read_in_source_order(tmp_path):
    table = read_frame_table(write_frames_csv(tmp_path / "frames.csv", [4, 0, 2]))
    assert table.source_index.tolist() == [0, 2, 4]
    assert table.names == ("frame_00000.png", "frame_00002.png", "frame_00004.png")
    # and states.csv lists the frames in that order, each under its own name
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,0\n4,door,1\n")
    compute_states(StatesConfig(key_frames=keys, frames=tmp_path / "frames.csv", out=tmp_path / "out",
                                method="linear"))
    states = pd.read_csv(tmp_path / "out" / "states.csv")
    assert states["source_index"].tolist() == [0, 2, 4]
    assert states["frame"].tolist() == ["frame_00000.png", "frame_00002.png", "frame_00004.png"]
    np.testing.assert_allclose(states["value"], [0.0, 0.5, 1.0])


def test_a_source_index_listed_twice_is_refused_wherever_the_rows_are(tmp_path):
    with pytest.raises(StateError, match="source_index 0 appears twice"):
        read_frame_table(write_frames_csv(tmp_path / "frames.csv", [4, 0, 2, 0]))


def test_pchip_hits_a_key_value_exactly_and_holds_it(tmp_path):
    """The cubic through (0,0), (10,0), (20,0), (30,0.1) evaluated at its last knot rounds to just under 0.1 in
    floating point; the documented behaviour is the key value itself, held beyond the last key frame."""
    out = interpolate(np.array([0.0, 10.0, 20.0, 30.0]), np.array([0.0, 0.0, 0.0, 0.1]), np.array([30.0, 35.0]),
                      "pchip")
    np.testing.assert_array_equal(out, [0.1, 0.1])
