"""The frames a pose run works on: image names and their source-video indices."""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from stages.scene import InputError, frame_number_of

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
FRAMES_FIRST = "run `livescene frames --video FOLDER --out FRAMES` first and pass FRAMES"


def image_names(folder: Path) -> list[str]:
    """Image files directly in ``folder``, sorted; hidden files are no frames, as in the frames stage: macOS leaves
    ``._IMG_0001.jpg`` (its metadata) beside every photo it copies to a foreign disk, named like the photo."""
    return sorted(p.name for p in Path(folder).iterdir()
                  if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file() and not p.name.startswith("."))


def frames_summary(frames_dir: Path) -> dict:
    """frames.json of a FRAMES folder; empty for a plain image folder, or one whose frames.json does not read as a
    mapping (what it would add is advice, not this stage's business to refuse)."""
    try:
        info = json.loads((Path(frames_dir) / "frames.json").read_text())
    except (OSError, ValueError):
        return {}
    return info if isinstance(info, dict) else {}


@dataclass
class FrameList:
    """Images of one capture in playback order."""

    image_dir: Path
    """Folder COLMAP reads the images from."""
    names: list[str]
    """Image file names, sorted (COLMAP's sequential matching pairs neighbours in name order)."""
    source_index: dict[str, int | None]
    """Name -> index of the frame in the source video (from frames.csv, else the number in the name)."""


def read_frame_list(frames_dir: Path) -> FrameList:
    """Images of a FRAMES folder (``images/`` + ``frames.csv``) or of a plain image folder."""
    frames_dir = Path(frames_dir)
    if not frames_dir.is_dir():
        raise InputError(frames_dir, "frames folder not found", "run `livescene frames` first or fix the path")
    image_dir = frames_dir / "images" if (frames_dir / "images").is_dir() else frames_dir
    names = image_names(image_dir)
    if not names:
        others = sorted({p.suffix.lower() for p in image_dir.iterdir() if p.is_file() and p.suffix})
        raise InputError(image_dir, f"no images ({', '.join(IMAGE_SUFFIXES)}) found"
                         + (f"; it holds {', '.join(others)} files" if others else ""),
                         "point --frames to the output of `livescene frames` (it holds images/; the frames stage "
                         "also reads .webp)")
    index: dict[str, int | None] = {}
    csv = frames_dir / "frames.csv"
    if csv.is_file():
        table = pd.read_csv(csv)
        if {"frame", "source_index"} <= set(table.columns):
            index = {str(f): int(s) for f, s in zip(table["frame"], table["source_index"], strict=True)}
    else:  # a plain folder: COLMAP reads its files as they are stored
        check_orientation(image_dir, names)
    for name in names:
        if name not in index:
            index[name] = frame_number_of(Path(name).stem)  # as the frames stage reads a folder's names
    return FrameList(image_dir=image_dir, names=names, source_index={n: index[n] for n in names})


def time_order(names: list[str], source_index: Mapping[str, int | None]) -> tuple[list[str], dict[str, float]]:
    """``names`` in playback order with their time: the source index, or the position in name order."""
    if all(source_index.get(n) is not None for n in names):
        ordered = sorted(names, key=lambda n: (source_index[n], n))
        return ordered, {n: float(source_index[n]) for n in ordered}  # type: ignore[arg-type]
    ordered = sorted(names)
    return ordered, {n: float(k) for k, n in enumerate(ordered)}


def check_orientation(image_dir: Path, names: list[str]) -> None:
    """Refuse photos whose EXIF orientation turns them: COLMAP reads the stored pixels, while every other stage
    (OpenCV) shows them turned, so poses, masks and training would disagree (``livescene frames`` turns them)."""
    from PIL import Image, UnidentifiedImageError

    for name in names:
        if Path(name).suffix.lower() not in (".jpg", ".jpeg", ".tif", ".tiff"):
            continue
        try:
            with Image.open(image_dir / name) as image:
                orientation = int(image.getexif().get(0x0112, 1))  # EXIF Orientation; reads the header only
        except (OSError, UnidentifiedImageError, ValueError, TypeError):
            continue  # an unreadable file is named by the stage that decodes it
        if orientation not in (0, 1):
            raise InputError(image_dir / name, f"its EXIF orientation ({orientation}) turns the stored pixels for "
                             "display; COLMAP reads them unturned, so poses would not fit the picture that masks "
                             "and training see", FRAMES_FIRST + " (it writes the frames turned upright)")


def check_name_order(frames: FrameList, ordered: list[str], matcher: str) -> None:
    """COLMAP's sequential matching pairs images in name order: refuse a folder whose name order is not its frame
    order (``IMG_10.jpg`` sorts before ``IMG_2.jpg``), which would pair frames far apart and break the model."""
    if matcher != "sequential" or ordered == frames.names:
        return
    k = next(k for k, n in enumerate(ordered) if frames.names[k] != n)
    raise InputError(frames.image_dir, f"COLMAP's sequential matching pairs images in name order, which is not "
                     f"their frame order here ({frames.names[k]} sorts before {ordered[k]}, an earlier frame)",
                     FRAMES_FIRST + " (its names sort in frame order), or pass --matcher exhaustive")
