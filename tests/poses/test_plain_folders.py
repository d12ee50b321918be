"""livescene poses on a plain folder of photos: refused before COLMAP when its name order is not the frame order
(sequential matching pairs by name) or when EXIF turns the pictures (COLMAP reads the stored pixels)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image

from stages.poses import PosesConfig, estimate_poses
from stages.poses.frame_list import read_frame_list
from stages.scene import InputError


def photos(folder: Path, names: list[str]) -> Path:
    folder.mkdir()
    rng = np.random.default_rng(0)
    for name in names:
        cv2.imwrite(str(folder / name), (rng.random((48, 64, 3)) * 255).astype(np.uint8))
    return folder


def test_names_that_sort_out_of_frame_order_are_refused_for_sequential_matching(tmp_path: Path) -> None:
    folder = photos(tmp_path / "shots", [f"img{k}.jpg" for k in range(12)])  # img10 sorts before img2
    frames = read_frame_list(folder)
    assert frames.source_index["img10.jpg"] == 10  # the number as the frames stage reads it
    cfg = PosesConfig(frames_dir=folder, out_dir=tmp_path / "poses", matcher="sequential")
    with pytest.raises(InputError, match=r"sequential matching pairs images in name order.*img10.jpg sorts before "
                                         r"img2.jpg, an earlier frame.*livescene frames --video FOLDER"):
        estimate_poses(cfg)
    assert not (tmp_path / "poses").exists()


def test_photos_turned_by_exif_are_refused(tmp_path: Path) -> None:
    folder = photos(tmp_path / "shots", [f"IMG_{k:04d}.jpg" for k in range(3)])
    read_frame_list(folder)  # upright photos pass
    turned = folder / "IMG_0001.jpg"
    image = Image.open(turned)
    exif = image.getexif()
    exif[0x0112] = 6  # "rotate 90 CW to display": how a phone held upright stores a photo
    image.save(turned, exif=exif)
    with pytest.raises(InputError, match=r"IMG_0001.jpg: its EXIF orientation \(6\) turns the stored pixels.*"
                                         r"fix: run `livescene frames --video FOLDER --out FRAMES` first"):
        read_frame_list(folder)


def test_a_folder_of_webp_names_the_frames_stage(tmp_path: Path) -> None:
    folder = tmp_path / "shots"
    folder.mkdir()
    (folder / "IMG_1.webp").write_bytes(b"RIFF")
    with pytest.raises(InputError, match=r"no images .* found; it holds \.webp files.*the frames stage also reads "
                                         r"\.webp"):
        read_frame_list(folder)


def test_macos_metadata_copies_are_no_frames(tmp_path: Path) -> None:
    # macOS writes ``._NAME`` (AppleDouble metadata, not an image) beside each photo it copies to a foreign disk
    folder = photos(tmp_path / "shots", [f"IMG_{k:04d}.JPG" for k in range(3)])
    for k in range(3):
        (folder / f"._IMG_{k:04d}.JPG").write_bytes(b"\x00\x05\x16\x07" + bytes(4000))
    frames = read_frame_list(folder)
    assert frames.names == ["IMG_0000.JPG", "IMG_0001.JPG", "IMG_0002.JPG"]
    assert frames.source_index == {"IMG_0000.JPG": 0, "IMG_0001.JPG": 1, "IMG_0002.JPG": 2}
