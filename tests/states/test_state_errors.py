"""Every bad key-frame input gets a message naming the file and the row."""

from __future__ import annotations

from pathlib import Path

import pytest
from state_files import write_frames_csv, write_text

from stages.states import StateError, StatesConfig, compute_states
from stages.states.cli import main as states_main

MAPPING = "1: door\n2: drawer\n"


def run(tmp: Path, key_file: Path, **kw) -> dict:
    frames = write_frames_csv(tmp / "frames.csv", list(range(0, 40, 2)))
    return compute_states(StatesConfig(key_frames=key_file, frames=frames, out=tmp / "out", **kw))


def test_nan_value_names_file_and_row(tmp_path):
    keys = write_text(tmp_path / "key_frame_value.yaml", """
frame_00000:
  door: 0.0
frame_00010:
  door: .nan
""")
    with pytest.raises(StateError, match=r"key_frame_value\.yaml: row 4: frame 'frame_00010', object 'door': value is "
                                         r"nan; fix: write a finite number"):
        run(tmp_path, keys)
    assert not (tmp_path / "out").exists()


def test_infinite_value_in_csv(tmp_path):
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,0\n10,door,inf\n")
    with pytest.raises(StateError, match=r"keys\.csv: row 3: frame '10', object 'door': value is inf"):
        run(tmp_path, keys)


def test_value_that_is_no_number(tmp_path):
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,0\n10,door,open\n")
    with pytest.raises(StateError, match=r"keys\.csv: row 3: .*value 'open' is not a number"):
        run(tmp_path, keys)


def test_a_fractional_frame_is_refused_not_truncated(tmp_path):
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,0\n10.5,door,1\n")
    with pytest.raises(StateError, match=r"keys\.csv: row 3: frame 10\.5 is not a whole frame index"):
        run(tmp_path, keys)
    keys = write_text(tmp_path / "key_frame_value.yaml", "0: {door: 0.0}\n2.5: {door: 1.0}\n")
    with pytest.raises(StateError, match=r"frame 2\.5 is not a whole frame index"):
        run(tmp_path, keys)


def test_a_csv_saved_with_a_byte_order_mark_is_read(tmp_path):
    keys = tmp_path / "keys.csv"
    keys.write_bytes("frame,object,value\n0,door,0\n10,door,1\n".encode("utf-8-sig"))
    summary = run(tmp_path, keys)
    assert summary["objects"] == ["door"]


def test_a_spreadsheets_csv_and_tsv_exports_are_read(tmp_path):
    """Capitalised headers, ``12.0`` frames (a table library's float column) and the empty rows a spreadsheet leaves
    below its data, comma- or tab-separated."""
    for sub in ("plain", "sheet/csv", "sheet/tsv"):
        (tmp_path / sub).mkdir(parents=True)
    plain = run(tmp_path / "plain", write_text(tmp_path / "plain.csv", "frame,object,value\n0,door,0\n12,door,1\n"))
    sheet = write_text(tmp_path / "sheet.csv", "Frame,Object,Value\r\n0.0,door,0\r\n12.0,door,1\r\n,,\r\n , , \r\n")
    tabs = write_text(tmp_path / "sheet.tsv", "frame\tobject\tvalue\n0\tdoor\t0\n12\tdoor\t1\n\t\t\n")
    for keys in (sheet, tabs):
        summary = run(tmp_path / keys.stem / keys.suffix[1:], keys)
        assert summary["objects"] == plain["objects"] == ["door"]
        assert summary["n_key_frames"] == plain["n_key_frames"]


def test_same_key_frame_with_two_values(tmp_path):
    # two spellings of source frame 10 (zero padding differs), annotated differently
    keys = write_text(tmp_path / "key_frame_value.yaml", """
frame_00000:
  door: 0.0
frame_00010:
  door: 1.0
img_10:
  door: 0.5
""")
    with pytest.raises(StateError, match=r"key_frame_value\.yaml: rows 4 and 6: key frame 10 of 'door' has two "
                                         r"different values \(1\.0 and 0\.5\)"):
        run(tmp_path, keys)


def test_same_key_frame_twice_with_the_same_value_is_fine(tmp_path):
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,0\n10,door,1\nframe_00010.png,door,1\n")
    assert run(tmp_path, keys)["n_key_frames"]["door"] == 2


def test_key_frame_for_a_frame_that_was_not_extracted(tmp_path):
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,0\n15,door,1\n")
    with pytest.raises(StateError, match=r"keys\.csv: row 3: key frame 15 \(door\) is a frame that does not exist in "
                                         r".*frames\.csv \(source indices 0\.\.38\)"):
        run(tmp_path, keys)
    summary = run(tmp_path, keys, allow_missing_frames=True)  # opt-in: used for interpolation only
    assert summary["n_key_frames"]["door"] == 2


def test_key_frame_between_extracted_frames_counts_when_the_video_holds_it(tmp_path):
    """frames.json says the video had 40 frames: frame 15 was skipped by subsampling, not invented."""
    (tmp_path / "frames.json").write_text('{"decoded_frame_count": 40}')
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,0\n15,door,1\n")
    assert run(tmp_path, keys)["n_key_frames"]["door"] == 2
    beyond = write_text(tmp_path / "beyond.csv", "frame,object,value\n0,door,0\n40,door,1\n")
    with pytest.raises(StateError, match=r"beyond\.csv: row 3: key frame 40 \(door\) is a frame that does not exist "
                                         r"in .*frames\.csv \(the source video has frames 0\.\.39\)"):
        run(tmp_path, beyond)


def test_object_never_annotated(tmp_path):
    mapping = write_text(tmp_path / "mapping.yaml", MAPPING)
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,0\n10,door,1\n")
    with pytest.raises(StateError, match=r"keys\.csv: objects \['drawer'\] of .*mapping\.yaml are never annotated"):
        run(tmp_path, keys, mapping=mapping)


def test_unknown_object_name(tmp_path):
    mapping = write_text(tmp_path / "mapping.yaml", MAPPING)
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,0\n0,drawer,0\n10,sofa,1\n")
    with pytest.raises(StateError, match=r"keys\.csv: row 4: unknown object 'sofa' \(objects of .*mapping\.yaml: "
                                         r"\['door', 'drawer'\]\)"):
        run(tmp_path, keys, mapping=mapping)


def test_unknown_conerf_class(tmp_path):
    write_text(tmp_path / "mapping.yml", "0: left eye\n")
    keys = write_text(tmp_path / "annotations.yml", """
- class: 0
  frame: 0
  value: -1
- class: 3
  frame: 10
  value: 1
""")
    with pytest.raises(StateError, match=r"annotations\.yml: row 4: unknown object: class 3 is not in .*mapping\.yml"):
        run(tmp_path, keys)


def test_value_outside_a_fixed_range(tmp_path):
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,0\n10,door,95\n")
    with pytest.raises(StateError, match=r"keys\.csv: row 3: value 95\.0 of 'door' lies outside the range "
                                         r"\[0\.0, 90\.0\] \(--range\)"):
        run(tmp_path, keys, ranges={"door": (0.0, 90.0)})


def test_missing_frames_csv_and_bad_columns(tmp_path):
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,0\n")
    with pytest.raises(StateError, match=r"nowhere\.csv: frames\.csv not found"):
        compute_states(StatesConfig(key_frames=keys, frames=tmp_path / "nowhere.csv", out=tmp_path / "o"))
    with pytest.raises(StateError, match=r"keys\.csv: row 1: header \['frame', 'thing', 'value'\] lacks"):
        run(tmp_path, write_text(tmp_path / "keys.csv", "frame,thing,value\n0,door,0\n"))


def test_cli_reports_error_and_exits_2(tmp_path, capsys):
    frames = write_frames_csv(tmp_path / "frames.csv", [0, 1, 2])
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,nan\n")
    code = states_main(["--key-frames", str(keys), "--frames", str(frames), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("error: ") and "row 2" in err and "value is nan" in err
    code = states_main(["--key-frames", str(keys), "--frames", str(frames), "--out", str(tmp_path / "out"),
                        "--range", "door=1,0"])
    assert code == 2 and "'door=1,0' is not OBJECT=LO,HI" in capsys.readouterr().err


def test_constant_value_outside_unit_range_needs_a_range(tmp_path):
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,5\n10,door,5\n")
    with pytest.raises(StateError, match=r"keys\.csv: row 2: 'door' has the single value 5\.0 on every key frame.*"
                                         r"--range door=LO,HI"):
        run(tmp_path, keys)
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,0.5\n10,door,0.5\n")
    assert run(tmp_path, keys)["ranges"]["door"]["source"] == "key values within [0, 1]: kept as given"


def test_option_for_an_unknown_object_or_method(tmp_path):
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n0,door,0\n10,door,1\n")
    with pytest.raises(StateError, match=r"keys\.csv: option names unknown object 'sofa' \(objects \['door'\]\)"):
        run(tmp_path, keys, object_methods={"sofa": "step"})
    with pytest.raises(StateError, match=r"--method: unknown method 'cubic'"):
        run(tmp_path, keys, method="cubic")


def test_key_frames_of_an_image_folder_numbered_by_the_camera(tmp_path, capsys):
    """Photos IMG_4501 .. IMG_4512 are frames 4501 .. 4512: a key frame on any of them counts, extracted or not, and
    one on a number the folder does not hold is refused with the folder's numbers."""
    import cv2
    import numpy as np

    from stages.frames.cli import main as frames_main

    photos = tmp_path / "photos"
    photos.mkdir()
    rng = np.random.default_rng(0)
    for i in range(4501, 4513):
        cv2.imwrite(str(photos / f"IMG_{i}.jpg"), rng.integers(0, 256, (24, 32, 3), dtype=np.uint8))
    frames = tmp_path / "frames"
    assert frames_main(["--video", str(photos), "--out", str(frames), "--count", "4", "--no-progress"]) == 0
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n4501,door,0\n4512,door,1\n")
    summary = compute_states(StatesConfig(key_frames=keys, frames=frames / "frames.csv", out=tmp_path / "out"))
    assert summary["n_key_frames"] == {"door": 2}
    bad = write_text(tmp_path / "bad.csv", "frame,object,value\n4501,door,0\n4000,door,1\n")
    with pytest.raises(StateError, match=r"key frame 4000 \(door\) is a frame that does not exist .*its 12 images "
                                         r"4501\.\.4512"):
        compute_states(StatesConfig(key_frames=bad, frames=frames / "frames.csv", out=tmp_path / "out2"))
