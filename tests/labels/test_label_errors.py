"""Every refusal of `livescene labels` names the file, the problem and the fix."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from labelset_writers import write_coco, write_labelme, write_png

from stages.labels import LabelError, LabelsConfig, ingest_labels
from stages.labels.cli import main as labels_main


def run(src: Path, frames: Path, out: Path, fmt: str = "auto", mapping: Path | None = None) -> dict:
    return ingest_labels(LabelsConfig(input=src, frames=frames, out=out, format=fmt, mapping=mapping, progress=False))


def test_non_integer_factor_is_refused(label_files):
    src = write_png(label_files.root, {f: lab[:32, :42] for f, lab in label_files.labels.items()})
    with pytest.raises(LabelError, match=r"frame_00000\.png: mask size cannot be matched.*42x32 -> 64x48.*integer"):
        run(src, label_files.frames, label_files.root / "out")
    assert not (label_files.root / "out").exists()  # nothing half-written


def test_png_value_missing_from_mapping(label_files):
    src = write_png(label_files.root, label_files.labels)
    path = src / "masks" / "frame_00002.png"
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    img[0, 0] = 9
    cv2.imwrite(str(path), img)
    with pytest.raises(LabelError, match=r"frame_00002\.png: pixel values \[9\] are no id of .*mapping\.yaml"):
        run(src, label_files.frames, label_files.root / "out")


def test_png_without_mapping(label_files):
    src = write_png(label_files.root, label_files.labels)
    (src / "mapping.yaml").unlink()
    with pytest.raises(LabelError, match=r"masks: png masks carry no object names.*pass --mapping"):
        run(src, label_files.frames, label_files.root / "out")


def test_labelme_unknown_label(label_files):
    src = write_labelme(label_files.root, label_files.labels)
    doc = json.loads((src / "0.json").read_text())
    doc["shapes"][0]["label"] = "sofa"
    (src / "0.json").write_text(json.dumps(doc))
    with pytest.raises(LabelError, match=r"0\.json: shapes\[0\] has label 'sofa', which is no object of .*\.yml"):
        run(src, label_files.frames, label_files.root / "out")


def test_coco_category_not_in_mapping(label_files):
    path = write_coco(label_files.root, label_files.labels)
    table = path.parent / "mapping.yaml"
    table.write_text(yaml.safe_dump({1: "door", 2: "drawer"}))
    with pytest.raises(LabelError, match=r"instances\.json: categories \['fridge'\] are not in .*mapping\.yaml"):
        run(path, label_files.frames, label_files.root / "out")


def test_coco_bad_rle_size(label_files):
    path = write_coco(label_files.root, label_files.labels)
    doc = json.loads(path.read_text())
    rle = next(a for a in doc["annotations"] if isinstance(a["segmentation"], dict))
    rle["segmentation"]["counts"] = [5, 5]
    path.write_text(json.dumps(doc))
    with pytest.raises(LabelError, match=r"annotations\[\d+\]: bad RLE \(run lengths add up to 10 pixels"):
        run(path, label_files.frames, label_files.root / "out")


def test_coco_annotations_of_no_image_and_shared_or_empty_category_names_are_refused(label_files):
    path = write_coco(label_files.root, label_files.labels)
    good = json.loads(path.read_text())
    orphan = json.loads(path.read_text())
    orphan["annotations"][0]["image_id"] = 12345
    path.write_text(json.dumps(orphan))
    with pytest.raises(LabelError, match=r"annotations\[0\] has image_id 12345 that no image defines"):
        run(path, label_files.frames, label_files.root / "out")
    for extra, message in (({"id": 9, "name": "door"}, r"categories \[\d+, 9\] share the name 'door'"),
                           ({"id": 9, "name": " "}, r"categories\[\d\] \(id 9\) has an empty name")):
        doc = json.loads(json.dumps(good))
        doc["categories"].append(extra)
        path.write_text(json.dumps(doc))
        with pytest.raises(LabelError, match=message):
            run(path, label_files.frames, label_files.root / "out")
    assert not (label_files.root / "out").exists()


def test_mixed_folder_needs_format(label_files):
    src = write_png(label_files.root, label_files.labels)
    np.save(src / "masks" / "00000.npy", np.zeros((2, 2, 4), bool))
    with pytest.raises(LabelError, match=r"cannot tell the label format: a mix of npy, png files.*--format"):
        run(src, label_files.frames, label_files.root / "out")


def test_no_label_matches_a_frame(label_files):
    src = write_png(label_files.root, {"00099": label_files.labels["00000"]})
    with pytest.raises(LabelError, match=r"none of the 1 labelled frames matches a frame"):
        run(src, label_files.frames, label_files.root / "out")


def test_cli_prints_error_and_exits_2(label_files, capsys):
    code = labels_main(["--input", str(label_files.root / "nowhere"), "--frames", str(label_files.frames),
                        "--out", str(label_files.root / "out")])
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "nowhere: label input not found" in err


def test_npy_with_the_wrong_channel_count(label_files):
    from labelset_writers import write_npy

    src = write_npy(label_files.root, label_files.labels)
    np.save(src / "masks" / "00002.npy", np.zeros((48, 64, 3), bool))
    with pytest.raises(LabelError, match=r"00002\.npy: mask has shape \(48, 64, 3\), expected H x W x 4"):
        run(src, label_files.frames, label_files.root / "out")


def test_frames_folder_without_images(label_files, tmp_path):
    empty = tmp_path / "empty_frames"
    (empty / "images").mkdir(parents=True)
    src = write_png(label_files.root, label_files.labels)
    with pytest.raises(LabelError, match=r"images: no images \(\.png/\.jpg\) found"):
        run(src, empty, label_files.root / "out")


def test_explicit_format_with_no_such_files(label_files):
    src = write_png(label_files.root, label_files.labels)
    with pytest.raises(LabelError, match=r"png: no npy label files found.*--format"):
        run(src, label_files.frames, label_files.root / "out", fmt="npy")
