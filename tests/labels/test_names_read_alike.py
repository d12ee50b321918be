"""Two objects whose names differ only in letter case or punctuation ("Drawer" and "drawer", "drawer-2" and
"drawer 2") are refused where the names are first read, naming the file: before, they went through labels, states,
assembly and training, and then no command or relevancy query could name either ("ambiguous object") and on a
file system that ignores case their export files were one."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from labelset_writers import make_label_maps, write_frames, write_png

from stages.capture import CaptureSpecError, spec_from_dict
from stages.labels import LabelError, LabelsConfig, ingest_labels
from stages.scene import SceneError, read_scene

TINY = Path(__file__).resolve().parents[2] / "config" / "captures" / "tiny.yaml"
ALIKE = [("Drawer", "drawer", "'drawer'"), ("drawer-2", "drawer 2", "'drawer 2'"),
         ("kid's drawer", "Kid S Drawer", "'kid s drawer'")]


@pytest.mark.parametrize(("a", "b", "read_as"), ALIKE)
def test_names_that_read_alike_are_refused_by_the_labels_stage(tmp_path, a, b, read_as):
    frames = write_frames(tmp_path)
    source = write_png(tmp_path, make_label_maps())
    (source / "mapping.yaml").write_text(yaml.safe_dump({3: a, 5: b, 7: "fridge"}, allow_unicode=True))
    with pytest.raises(LabelError, match=f"mapping.yaml: .*differ only in letter case or punctuation.*{read_as}"):
        ingest_labels(LabelsConfig(input=source, frames=frames, out=tmp_path / "labels", progress=False))


def test_names_that_read_alike_are_refused_in_a_capture_spec_and_a_dataset(tiny_dataset):
    spec = yaml.safe_load(TINY.read_text())
    spec["objects"][1]["name"] = "Cabinet"
    with pytest.raises(CaptureSpecError, match="'cabinet' and 'Cabinet' differ only in letter case"):
        spec_from_dict(spec)
    (tiny_dataset.root / "mapping.yaml").write_text("1: object0\n2: Object0\n3: object2\n")
    with pytest.raises(SceneError, match=r"mapping\.yaml: object names 'object0' and 'Object0' differ only"):
        read_scene(tiny_dataset.root)


def test_names_that_only_look_alike_are_kept(tmp_path):
    frames = write_frames(tmp_path)
    source = write_png(tmp_path, make_label_maps())
    names = ["drawer-2", "2nd drawer", "冰箱"]
    (source / "mapping.yaml").write_text(yaml.safe_dump(dict(zip((3, 5, 7), names, strict=True)), allow_unicode=True))
    ingest_labels(LabelsConfig(input=source, frames=frames, out=tmp_path / "labels", progress=False))
    assert list(yaml.safe_load((tmp_path / "labels" / "mapping.yaml").read_text()).values()) == names


@pytest.mark.parametrize("word", ["yes", "on", "No", "TRUE", "null"])
def test_a_name_yaml_reads_as_a_boolean_or_nothing_is_refused_with_the_quoting_fix(tmp_path, tiny_dataset, word):
    """`1: yes` in a hand-written mapping.yaml was the object "True" (and `1: on` too) in every later file."""
    frames = write_frames(tmp_path)
    source = write_png(tmp_path, make_label_maps())
    (source / "mapping.yaml").write_text(f"3: {word}\n5: drawer\n7: fridge\n")
    with pytest.raises(LabelError, match=r"mapping\.yaml: id 3.*fix: .*(quote the name|`1: 'null'`)"):
        ingest_labels(LabelsConfig(input=source, frames=frames, out=tmp_path / "labels", progress=False))
    (tiny_dataset.root / "mapping.yaml").write_text(f"1: {word}\n2: drawer\n3: fridge\n")
    with pytest.raises(SceneError, match=r"mapping\.yaml: id 1: YAML reads the name as .*fix: quote the name"):
        read_scene(tiny_dataset.root)
    (source / "mapping.yaml").write_text(f"3: '{word}'\n5: drawer\n7: fridge\n")
    ingest_labels(LabelsConfig(input=source, frames=frames, out=tmp_path / "labels", progress=False))
    assert yaml.safe_load((tmp_path / "labels" / "mapping.yaml").read_text())[1] == word
