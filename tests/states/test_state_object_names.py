"""Object names that a CSV reader would take for something else survive states.csv: pandas reads "null", "NA"
and "None" as missing values and "2" as a number unless told not to."""

from __future__ import annotations

from state_files import write_frames_csv, write_text

from stages.states import StatesConfig, compute_states, read_states_csv


def test_names_a_csv_reader_would_convert_survive_states_csv(tmp_path):
    names = ["null", "NA", "None", "2", "kid's drawer", 'left, "big" drawer']
    rows = "".join(f'0,"{n.replace(chr(34), 2 * chr(34))}",0\n10,"{n.replace(chr(34), 2 * chr(34))}",1\n'
                   for n in names)
    keys = write_text(tmp_path / "keys.csv", "frame,object,value\n" + rows)
    frames = write_frames_csv(tmp_path / "frames.csv", list(range(11)))
    compute_states(StatesConfig(key_frames=keys, frames=frames, out=tmp_path / "out"))
    table = read_states_csv(tmp_path / "out")
    assert list(dict.fromkeys(table["object"])) == names
    assert table["value"].dtype.kind == "f"
