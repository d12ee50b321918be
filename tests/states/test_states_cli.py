"""`livescene states` end to end: dense states, key-frame flags, normalisation, report, per-object methods."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
import yaml
from state_files import write_frames_csv, write_text

from stages.states.cli import main as states_main


def test_livescene_key_frames_to_dense_states(tmp_path, capsys):
    frames = write_frames_csv(tmp_path / "frames.csv", list(range(0, 30)))
    keys = write_text(tmp_path / "key_frame_value.yaml", """
frame_00004:
  door: 0.0
  drawer: 0.0
frame_00010:
  door: 1.0
frame_00011:
  drawer: 0.5
frame_00020:
  door: 0.25
  drawer: 1.0
""")
    out = tmp_path / "states"
    assert states_main(["--key-frames", str(keys), "--frames", str(frames), "--out", str(out),
                        "--method", "pchip", "--method", "drawer=step"]) == 0
    assert "door: 3 key frames, method pchip" in capsys.readouterr().out
    table = pd.read_csv(out / "states.csv")
    assert list(table.columns) == ["frame", "source_index", "object", "value", "is_key_frame"]
    assert len(table) == 60
    door = table[table.object == "door"].set_index("source_index")
    drawer = table[table.object == "drawer"].set_index("source_index")
    assert door.loc[0, "value"] == 0.0 and door.loc[29, "value"] == 0.25  # held outside the key frames
    assert door.loc[10, "value"] == 1.0 and door.loc[10, "is_key_frame"]
    assert not door.loc[11, "is_key_frame"] and drawer.loc[11, "is_key_frame"]
    assert drawer.loc[15, "value"] == 0.5  # step holds the last key value
    assert door.loc[:, "value"].between(0, 1).all()
    report = json.loads((out / "states.json").read_text())
    assert report["methods"] == {"door": "pchip", "drawer": "step"}
    assert report["ranges"]["door"] == {"lo": 0.0, "hi": 1.0, "source": "key values within [0, 1]: kept as given"}
    assert report["leave_one_out"]["door"]["linear"]["n"] == 1
    # predicting frame 10 from 4 and 20 linearly: 0 + (1 - 4/16... ) -> 6/16 * 0.25 = 0.09375, error 0.90625
    assert report["leave_one_out"]["door"]["linear"]["mae"] == pytest.approx(1 - 0.25 * 6 / 16)
    assert yaml.safe_load((out / "key_frame_value.yaml").read_text())["frame_00011"] == {"drawer": 0.5}


def test_min_max_and_fixed_ranges_normalise(tmp_path):
    frames = write_frames_csv(tmp_path / "frames.csv", list(range(0, 11)))
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,10\n10,door,90\n0,lid,0\nframe_00010,lid,45\n")
    out = tmp_path / "states"
    assert states_main(["--key-frames", str(keys), "--frames", str(frames), "--out", str(out), "--method", "linear",
                        "--range", "lid=0,90"]) == 0
    table = pd.read_csv(out / "states.csv")
    door = table[table.object == "door"]["value"].to_numpy()
    lid = table[table.object == "lid"]["value"].to_numpy()
    np.testing.assert_allclose(door, np.linspace(0, 1, 11))
    np.testing.assert_allclose(lid, np.linspace(0, 0.5, 11))
    ranges = json.loads((out / "states.json").read_text())["ranges"]
    assert ranges["door"]["lo"] == 10 and ranges["door"]["hi"] == 90 and ranges["lid"]["source"] == "--range"


def test_unit_values_are_kept_and_an_object_that_stays_shut_is_named(tmp_path, capsys):
    # the bedroom capture's wardrobe: shut all along, annotated with noise; min-max read 0.029 as fully open
    frames = write_frames_csv(tmp_path / "frames.csv", list(range(0, 31)))
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,wardrobe,0\n10,wardrobe,0.029\n20,wardrobe,0.003\n"
                                             "30,wardrobe,0\n0,drawer,0.1\n10,drawer,0.6\n20,drawer,0.9\n30,drawer,0.2\n")
    out = tmp_path / "states"
    args = ["--key-frames", str(keys), "--frames", str(frames), "--out", str(out), "--method", "linear"]
    assert states_main(args) == 0
    assert "'wardrobe' barely moves in its key frames (values span 0.029" in capsys.readouterr().err
    table = pd.read_csv(out / "states.csv")
    assert table[table.object == "wardrobe"]["value"].max() == pytest.approx(0.029)
    assert table[table.object == "drawer"]["value"].tolist()[10] == pytest.approx(0.6)  # not stretched to [0, 1]
    report = json.loads((out / "states.json").read_text())
    assert report["still"] == ["wardrobe"] and report["key_span"]["drawer"] == pytest.approx(0.8)


def test_conerf_annotations_map_minus_one_one_to_unit_range(tmp_path):
    frames = write_frames_csv(tmp_path / "frames.csv", list(range(0, 21)))
    write_text(tmp_path / "mapping.yml", "0: left eye\n1: mouth\n")
    keys = write_text(tmp_path / "annotations.yml", """
- class: 0
  frame: 0
  value: -1
- class: 0
  frame: 20
  value: 1
- class: 1
  frame: 10
  value: 0
""")
    out = tmp_path / "states"
    assert states_main(["--key-frames", str(keys), "--frames", str(frames), "--out", str(out)]) == 0
    table = pd.read_csv(out / "states.csv")
    eye = table[table.object == "left eye"].set_index("source_index")["value"]
    assert eye[0] == 0.0 and eye[20] == 1.0 and eye[10] == pytest.approx(0.5)
    assert (table[table.object == "mouth"]["value"] == 0.5).all()  # one key frame: held everywhere
    assert json.loads((out / "states.json").read_text())["ranges"]["mouth"]["source"] == "conerf convention"
