"""Object names become parts of file names (a combination's folder, each object's part files, grounding maps): a
file name holds 255 bytes, which three names of 100 letters, or one of 100 CJK characters (3 bytes each), passed,
so the export failed after training with "File name too long". Letters of any script are kept in the folder."""

from __future__ import annotations

import json

from stages.evaluate.evaluation import grounding_figure
from stages.export.exporter import file_stem
from stages.export.state_spec import state_slug
from stages.report.export_section import section_export

LONG = [("the long oak cabinet by the window with brass handles " * 2)[:97] + f" {i:02d}" for i in range(3)]


def test_a_combination_of_long_names_is_a_folder_name(tmp_path):
    assert all(len(n) == 100 for n in LONG)
    slugs = {state_slug(dict.fromkeys(LONG, v)) for v in (0.0, 0.5, 1.0)}
    assert len(slugs) == 3
    for slug in slugs:
        assert len(slug.encode()) <= 255
        (tmp_path / slug).mkdir()
    assert state_slug({"冰箱": 1.0, "шкаф": 0.0}) == "冰箱-1_шкаф-0"  # before: "--1_--0"
    assert state_slug({"cabinet": 1.0, "top_drawer": 0.0}) == "cabinet-1_top-drawer-0"  # as before


def test_part_files_and_grounding_maps_of_a_long_name_can_be_written(tmp_path):
    name = "冰" * 100
    for file in (f"{file_stem(name)}_points.ply", grounding_figure("language_objects", name, "00000")):
        assert len(file.encode()) <= 255
        (tmp_path / file).write_bytes(b"")
    assert file_stem(name) != file_stem("冰" * 99 + "箱")
    assert file_stem("kid's drawer") == "kid's drawer"  # a short name is its own file name, as before


def test_the_report_finds_the_part_of_a_long_named_object(tmp_path):
    name = "冰" * 100
    (tmp_path / "export.json").write_text(json.dumps({
        "objects": [name], "options": {"objects": True},
        "exports": [{"states": {name: 1.0}, "timings_s": {},
                     "files": {f"objects/{file_stem(name)}_mesh": {"vertices": 3, "triangles": 1, "bytes": 100}}}]}))
    assert "3 v / 1 t" in section_export({"livescene": tmp_path})
