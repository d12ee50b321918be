"""The same 3-object label set in all four formats ingests to identical canonical masks."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from labelset_writers import HEIGHT, NAMES, WIDTH, write_coco, write_labelme, write_npy, write_png

from stages.labels import LabelsConfig, decode_rle, encode_counts_string, encode_rle, ingest_labels
from stages.labels.cli import main as labels_main
from stages.scene import onehot_to_label_map


def ingest(src: Path, frames: Path, out: Path, fmt: str = "auto", mapping: Path | None = None,
           missing_masks: str = "propagate") -> dict:
    return ingest_labels(LabelsConfig(input=src, frames=frames, out=out, format=fmt, mapping=mapping, progress=False,
                                      missing_masks=missing_masks))


def read_masks(out: Path) -> dict[str, np.ndarray]:
    return {p.stem: np.load(p) for p in sorted((out / "masks").glob("*.npy"))}


def test_four_formats_give_identical_canonical_masks(label_files):
    root, labels = label_files.root, label_files.labels
    sources = {
        "png": write_png(root, labels),
        "npy": write_npy(root, labels),
        "coco": write_coco(root, labels),
        "labelme": write_labelme(root, labels),
    }
    results = {}
    for fmt, src in sources.items():
        summary = ingest(src, label_files.frames, root / f"out_{fmt}", missing_masks="leave")
        assert summary["format"] == fmt  # auto detection
        assert summary["objects"] == list(NAMES)
        results[fmt] = read_masks(root / f"out_{fmt}")
        assert yaml.safe_load((root / f"out_{fmt}" / "mapping.yaml").read_text()) == {1: "door", 2: "drawer",
                                                                                       3: "fridge"}
    reference = results["png"]
    assert sorted(reference) == ["00000", "00002", "00004"]
    for fid, mask in reference.items():
        assert mask.dtype == bool and mask.shape == (HEIGHT, WIDTH, 4)
        assert (mask.sum(-1) == 1).all()
        expected = np.where(labels[fid] == 0, 3, labels[fid].astype(np.int64) - 1)
        np.testing.assert_array_equal(onehot_to_label_map(mask), expected)
    for fmt, masks in results.items():
        assert sorted(masks) == sorted(reference), fmt
        for fid in reference:
            np.testing.assert_array_equal(masks[fid], reference[fid], err_msg=f"{fmt} frame {fid}")


def test_labels_json_reports_coverage_missing_and_unreliable_frames(label_files):
    src = write_png(label_files.root, label_files.labels)
    out = label_files.root / "out"
    ingest(src, label_files.frames, out, missing_masks="leave")  # the default would propagate to frame 00006
    summary = json.loads((out / "labels.json").read_text())
    assert summary["frames_without_masks"] == ["00006"]
    assert summary["min_reliable_pixels"] == pytest.approx(HEIGHT * WIDTH / 300)
    assert summary["unreliable_frames"] == {"00004": ["fridge"]}
    for fid, lab in label_files.labels.items():
        for k, name in enumerate(NAMES, start=1):
            n = int((lab == k).sum())
            assert summary["frames"][fid]["pixels"][name] == n
            assert summary["frames"][fid]["coverage"][name] == pytest.approx(n / (HEIGHT * WIDTH), abs=1e-6)


def test_integer_factor_resizes_nearest(label_files):
    src = write_png(label_files.root, {f: lab[::2, ::2] for f, lab in label_files.labels.items()})
    out = label_files.root / "out"
    summary = ingest(src, label_files.frames, out)
    assert summary["source_sizes"] == [[WIDTH // 2, HEIGHT // 2]]
    small = label_files.labels["00000"][::2, ::2]
    up = np.repeat(np.repeat(small, 2, 0), 2, 1).astype(np.int64)
    np.testing.assert_array_equal(onehot_to_label_map(read_masks(out)["00000"]), np.where(up == 0, 3, up - 1))


def test_downscale_by_integer_factor(label_files):
    big = {f: np.repeat(np.repeat(lab, 3, 0), 3, 1) for f, lab in label_files.labels.items()}
    out = label_files.root / "out"
    ingest(write_png(label_files.root, big), label_files.frames, out)
    lab = label_files.labels["00002"].astype(np.int64)
    np.testing.assert_array_equal(onehot_to_label_map(read_masks(out)["00002"]), np.where(lab == 0, 3, lab - 1))


def test_rle_round_trip_both_forms():
    rng = np.random.default_rng(0)
    for _ in range(20):
        mask = rng.random((7, 9)) < rng.random()
        runs = encode_rle(mask)
        assert sum(runs) == mask.size
        np.testing.assert_array_equal(decode_rle(runs, 7, 9), mask)
        np.testing.assert_array_equal(decode_rle(encode_counts_string(runs), 7, 9), mask)


def test_rle_decoder_reads_a_known_coco_string():
    # a 3x3 mask with the centre pixel set: runs [4, 1, 4] in column-major order -> "414"
    assert encode_counts_string([4, 1, 4]) == "414"
    mask = decode_rle("414", 3, 3)
    assert mask.sum() == 1 and mask[1, 1]


def test_cli_writes_and_reports(label_files, capsys):
    src = write_png(label_files.root, label_files.labels)
    out = label_files.root / "cli_out"
    assert labels_main(["--input", str(src), "--frames", str(label_files.frames), "--out", str(out),
                        "--format", "png", "--no-progress"]) == 0
    assert "3/4 frames labelled" in capsys.readouterr().out
    assert (out / "labels.json").is_file()


def test_npy_overlaps_go_to_the_later_object_and_empty_pixels_to_background(label_files):
    src = write_npy(label_files.root, label_files.labels)
    path = src / "masks" / "00000.npy"
    mask = np.load(path)
    mask[0, 0] = [True, False, True, False]  # door and fridge both claim the pixel
    mask[0, 1] = False  # no channel at all
    np.save(path, mask)
    summary = ingest(src, label_files.frames, label_files.root / "out")
    out = read_masks(label_files.root / "out")["00000"]
    assert out[0, 0].tolist() == [False, False, True, False]
    assert out[0, 1].tolist() == [False, False, False, True]
    assert summary["overlap_pixels"] == {"00000": 1}


def _davis_palette() -> list[int]:
    """DAVIS's colour map (what XMem, Cutie and SAM 2's video demos save): index 1 dark red, 2 dark green, ..."""
    palette = []
    for index in range(256):
        rgb, c = [0, 0, 0], index
        for shift in range(7, -1, -1):
            for channel in range(3):
                rgb[channel] |= ((c >> channel) & 1) << shift
            c >>= 3
        palette += rgb
    return palette


def test_palette_pngs_are_read_by_their_indices(label_files):
    from PIL import Image

    grey = write_png(label_files.root, label_files.labels)
    palette = label_files.root / "palette"
    (palette / "masks").mkdir(parents=True)
    for path in sorted((grey / "masks").glob("*.png")):
        image = Image.fromarray(np.asarray(Image.open(path)), mode="P")
        image.putpalette(_davis_palette())
        image.save(palette / "masks" / path.name)
    (palette / "mapping.yaml").write_text((grey / "mapping.yaml").read_text())
    assert Image.open(next((palette / "masks").glob("*.png"))).mode == "P"
    ingest(grey, label_files.frames, label_files.root / "out_grey", missing_masks="leave")
    summary = ingest(palette, label_files.frames, label_files.root / "out_palette", missing_masks="leave")
    assert summary["format"] == "png" and summary["objects"] == list(NAMES)
    grey_masks, palette_masks = read_masks(label_files.root / "out_grey"), read_masks(label_files.root / "out_palette")
    assert sorted(palette_masks) == sorted(grey_masks) == ["00000", "00002", "00004"]
    for fid in grey_masks:
        np.testing.assert_array_equal(palette_masks[fid], grey_masks[fid])


def test_a_colour_mask_that_is_not_a_palette_is_refused_with_the_fix(label_files, capsys):
    import cv2

    src = write_png(label_files.root, label_files.labels)
    for path in (src / "masks").glob("*.png"):  # the palette's colours written out as RGB: no ids left
        ids = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        cv2.imwrite(str(path), np.stack([ids, ids // 2, np.zeros_like(ids)], axis=-1))
    assert labels_main(["--input", str(src), "--frames", str(label_files.frames), "--out",
                        str(label_files.root / "out"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "id map has colour channels that differ" in err and "palette PNG whose values are the object ids" in err
    assert not (label_files.root / "out").exists()


def _write_object_folders(root: Path, labels: dict[str, np.ndarray], names=NAMES, colour: bool = False) -> Path:
    """One folder of binary masks per object (white on black; 3-channel with ``colour``), named after it."""
    import cv2

    out = root / "objects"
    for k, name in enumerate(names, start=1):
        (out / name).mkdir(parents=True)
        for fid, lab in labels.items():
            mask = np.where(lab == k, 255, 0).astype(np.uint8)
            cv2.imwrite(str(out / name / f"{fid}.png"), np.dstack([mask] * 3) if colour else mask)
    return out


def test_one_mask_folder_per_object_gives_the_same_masks(label_files):
    grey = write_png(label_files.root, label_files.labels)
    ingest(grey, label_files.frames, label_files.root / "out_grey", missing_masks="leave")
    reference = read_masks(label_files.root / "out_grey")
    src = _write_object_folders(label_files.root, label_files.labels, colour=True)
    summary = ingest(src, label_files.frames, label_files.root / "out_objects", missing_masks="leave")
    assert summary["format"] == "objects" and summary["objects"] == sorted(NAMES)  # sorted folder names
    masks = read_masks(label_files.root / "out_objects")
    assert sorted(masks) == sorted(reference)
    for fid in reference:
        np.testing.assert_array_equal(masks[fid], reference[fid])  # NAMES are already sorted: same channels

    # a mapping.yaml beside the folders sets the order; its names must be the folders'
    (src / "mapping.yaml").write_text(yaml.safe_dump({1: "fridge", 2: "door", 3: "drawer"}))
    summary = ingest(src, label_files.frames, label_files.root / "out_ordered", missing_masks="leave")
    assert summary["objects"] == ["fridge", "door", "drawer"]
    ordered = read_masks(label_files.root / "out_ordered")
    np.testing.assert_array_equal(ordered["00000"][..., [1, 2, 0, 3]], reference["00000"])


def test_object_folders_refuse_a_frame_some_objects_lack_and_names_the_table_lacks(label_files, capsys):
    src = _write_object_folders(label_files.root, label_files.labels)
    (src / "drawer" / "00002.png").unlink()
    out = label_files.root / "out"
    args = ["--input", str(src), "--frames", str(label_files.frames), "--out", str(out), "--no-progress"]
    assert labels_main(args) == 2
    err = capsys.readouterr().err
    assert "1 frames have masks for some objects only (frame 2 has none for ['drawer'])" in err
    assert "an empty mask where it is not visible" in err and not out.exists()
    (src / "drawer").rename(src / "chest")
    (src / "mapping.yaml").write_text(yaml.safe_dump({1: "door", 2: "drawer", 3: "fridge"}))
    assert labels_main(args) == 2
    err = capsys.readouterr().err
    assert "folders without a name: ['chest']; names without a folder: ['drawer']" in err and not out.exists()


def test_jpeg_masks_are_refused_and_upper_case_png_is_read(label_files, capsys):
    src = _write_object_folders(label_files.root, label_files.labels)
    for p in (src / "door").iterdir():  # one object's masks exported as JPEG: never silently left out
        p.rename(p.with_suffix(".jpg"))
    out = label_files.root / "out"
    args = ["--input", str(src), "--frames", str(label_files.frames), "--out", str(out), "--no-progress",
            "--missing-masks", "leave"]
    assert labels_main(args) == 2
    err = capsys.readouterr().err
    assert f"{src / 'door'}: " in err and "masks are JPEG" in err and "export the masks as PNG" in err
    for p in (src / "door").iterdir():
        p.rename(p.with_suffix(".PNG"))
    assert labels_main(args) == 0
    ingest(write_png(label_files.root, label_files.labels), label_files.frames, label_files.root / "out_grey",
           missing_masks="leave")
    reference = read_masks(label_files.root / "out_grey")
    masks = read_masks(out)
    assert sorted(masks) == sorted(reference)
    for fid in reference:
        np.testing.assert_array_equal(masks[fid], reference[fid])


def test_files_of_no_frame_and_objects_no_mask_shows_are_said_on_stderr(label_files, capsys):
    import shutil

    src = write_png(label_files.root, label_files.labels)
    first = sorted((src / "masks").iterdir())[0]
    shutil.copyfile(first, src / "masks" / "mask.png")  # no frame number: matches no frame
    table = yaml.safe_load((src / "mapping.yaml").read_text())
    table[250] = "oven"  # named, but no mask has its id
    (src / "mapping.yaml").write_text(yaml.safe_dump(table))
    summary = ingest(src, label_files.frames, label_files.root / "out", missing_masks="leave")
    err = capsys.readouterr().err
    assert "1 label file(s) match no extracted frame" in err and "mask.png" in err
    assert "no mask shows ['oven'] in any frame" in err
    assert summary["labels_without_frame"] == [str(src / "masks" / "mask.png")]


def _reference_masks(label_files) -> dict[str, np.ndarray]:
    ingest(write_png(label_files.root, label_files.labels), label_files.frames, label_files.root / "out_grey",
           missing_masks="leave")
    return read_masks(label_files.root / "out_grey")


def test_cut_out_masks_take_their_alpha_and_an_opaque_alpha_is_no_object(label_files):
    """A cut-out (the object opaque on a transparent background, white or the photo's colours everywhere) is its
    alpha; a mask with an opaque alpha channel is its colour (the alpha is no object pixel)."""
    import cv2

    reference = _reference_masks(label_files)
    src = _write_object_folders(label_files.root, label_files.labels)
    rng = np.random.default_rng(0)
    for path in src.glob("*/*.png"):
        mask = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        photo = rng.integers(0, 256, (*mask.shape, 3), dtype=np.uint8)  # colours everywhere, black pixels too
        cv2.imwrite(str(path), np.dstack([photo, mask]))
    ingest(src, label_files.frames, label_files.root / "out_cutout", missing_masks="leave")
    for path in src.glob("*/*.png"):  # opaque white on opaque black
        mask = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)[..., 3]
        cv2.imwrite(str(path), np.dstack([mask, mask, mask, np.full_like(mask, 255)]))
    ingest(src, label_files.frames, label_files.root / "out_opaque", missing_masks="leave")
    for out in ("out_cutout", "out_opaque"):
        masks = read_masks(label_files.root / out)
        assert sorted(masks) == sorted(reference)
        for fid in reference:
            np.testing.assert_array_equal(masks[fid], reference[fid])


def test_object_folders_named_or_padded_differently_pair_by_frame_number(label_files):
    reference = _reference_masks(label_files)
    src = _write_object_folders(label_files.root, label_files.labels)
    for path in (src / "drawer").iterdir():  # 00002.png -> IMG_2.png: another tool's naming for one object
        path.rename(path.with_name(f"IMG_{int(path.stem)}.png"))
    (src / "door" / "._00000.png").write_bytes(b"Mac OS X        ")  # macOS metadata beside a copied file
    (src / "._drawer.png").write_bytes(b"Mac OS X        ")
    ingest(src, label_files.frames, label_files.root / "out", missing_masks="leave")
    masks = read_masks(label_files.root / "out")
    assert sorted(masks) == sorted(reference)
    for fid in reference:
        np.testing.assert_array_equal(masks[fid], reference[fid])
    (src / "drawer" / "frame_0002.png").write_bytes((src / "drawer" / "IMG_2.png").read_bytes())
    with pytest.raises(Exception, match=r"two masks name frame 2 \(IMG_2.png, frame_0002.png\)"):
        ingest(src, label_files.frames, label_files.root / "out2", missing_masks="leave")


def test_id_maps_with_an_alpha_channel_and_names_in_another_form_are_read(label_files):
    import cv2

    reference = _reference_masks(label_files)
    src = write_png(label_files.root / "alpha", label_files.labels)
    for path in sorted((src / "masks").glob("*.png")):
        ids = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        fid = int(path.stem.rsplit("_", 1)[-1])
        cv2.imwrite(str(path.with_name(f"img{fid}.png")), np.dstack([ids, ids, ids, np.full_like(ids, 255)]))
        path.unlink()
    ingest(src, label_files.frames, label_files.root / "out_alpha", missing_masks="leave")
    masks = read_masks(label_files.root / "out_alpha")
    assert sorted(masks) == sorted(reference)
    for fid in reference:
        np.testing.assert_array_equal(masks[fid], reference[fid])


def test_full_size_masks_map_onto_frames_the_frames_stage_downscaled_by_a_rounded_factor(tmp_path):
    """``frames --max-side`` divides both sides by one integer and rounds (4032x3024 / 5 -> 806x605); masks drawn on
    the full-size photos are sampled under each frame pixel's centre instead of refused."""
    import cv2

    from stages.frames.cli import main as frames_main

    width, height = 403, 302  # / 5 -> 80.6 x 60.4: written 81 x 60
    photos, masks = tmp_path / "photos", tmp_path / "masks"
    photos.mkdir()
    masks.mkdir()
    ids = np.zeros((height, width), np.uint8)
    ids[40:200, 50:170] = 1
    ids[150:290, 250:390] = 2
    rng = np.random.default_rng(0)
    for i in range(3):
        cv2.imwrite(str(photos / f"IMG_{i:04d}.jpg"), rng.integers(0, 256, (height, width, 3), dtype=np.uint8))
        cv2.imwrite(str(masks / f"IMG_{i:04d}.png"), ids)
    (masks / "mapping.yaml").write_text(yaml.safe_dump({1: "door", 2: "drawer"}))
    frames = tmp_path / "frames"
    assert frames_main(["--video", str(photos), "--out", str(frames), "--max-side", "96", "--no-progress"]) == 0
    assert cv2.imread(str(frames / "images" / "frame_00000.png")).shape[:2] == (60, 81)
    ingest(masks, frames, tmp_path / "out", missing_masks="leave")
    channel = onehot_to_label_map(np.load(tmp_path / "out" / "masks" / "00001.npy"))  # background last (2)
    got = np.where(channel == 2, 0, channel + 1)
    rows = ((np.arange(60) + 0.5) * height / 60).astype(int)
    cols = ((np.arange(81) + 0.5) * width / 81).astype(int)
    np.testing.assert_array_equal(got, ids[rows][:, cols])
    assert abs((got == 1).mean() - (ids == 1).mean()) < 0.01 and abs((got == 2).mean() - (ids == 2).mean()) < 0.01
