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


def test_a_name_with_spaces_around_it_is_named_as_the_labels_stage_names_it(tmp_path):
    """The labels stage strips a name's outer spaces; the states stage kept them, so `dataset assemble` refused
    states for 'cabinet ' against labels for 'cabinet' (a difference the message's lists barely show)."""
    from stages.labels.name_table import read_name_table

    mapping = write_text(tmp_path / "mapping.yaml", "1: 'cabinet '\n2: '  2nd  drawer'\n")
    keys = write_text(tmp_path / "key_frame_value.yaml", "frame_00000: {'cabinet ': 0, '  2nd  drawer': 0}\n"
                                                         "frame_00010: {'cabinet ': 1, '  2nd  drawer': 1}\n")
    frames = write_frames_csv(tmp_path / "frames.csv", list(range(11)))
    compute_states(StatesConfig(key_frames=keys, frames=frames, out=tmp_path / "out", mapping=mapping))
    names = list(dict.fromkeys(read_states_csv(tmp_path / "out")["object"]))
    assert names == list(read_name_table(mapping).names) == ["cabinet", "2nd  drawer"]
