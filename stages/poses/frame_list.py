"""The frames a pose run works on: image names and their source-video indices."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from stages.scene import InputError, frame_id_of

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


@dataclass
class FrameList:
    """Images of one capture in playback order."""

    image_dir: Path
    """Folder COLMAP reads the images from."""
    names: list[str]
    """Image file names, sorted (COLMAP's sequential matching pairs neighbours in name order)."""
    source_index: dict[str, int | None]
    """Name -> index of the frame in the source video (from frames.csv, else the numeric frame id)."""


def read_frame_list(frames_dir: Path) -> FrameList:
    """Images of a FRAMES folder (``images/`` + ``frames.csv``) or of a plain image folder."""
    frames_dir = Path(frames_dir)
    if not frames_dir.is_dir():
        raise InputError(frames_dir, "frames folder not found", "run `livescene frames` first or fix the path")
    image_dir = frames_dir / "images" if (frames_dir / "images").is_dir() else frames_dir
    names = sorted(p.name for p in image_dir.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())
    if not names:
        raise InputError(image_dir, "no images (.png/.jpg) found",
                         "point --frames to the output of `livescene frames` (it holds images/)")
    index: dict[str, int | None] = {}
    csv = frames_dir / "frames.csv"
    if csv.is_file():
        table = pd.read_csv(csv)
        if {"frame", "source_index"} <= set(table.columns):
            index = {str(f): int(s) for f, s in zip(table["frame"], table["source_index"], strict=True)}
    for name in names:
        if name not in index:
            fid = frame_id_of(Path(name).stem)
            index[name] = int(fid) if fid.isdigit() else None
    return FrameList(image_dir=image_dir, names=names, source_index={n: index[n] for n in names})


def time_order(names: list[str], source_index: Mapping[str, int | None]) -> tuple[list[str], dict[str, float]]:
    """``names`` in playback order with their time: the source index, or the position in name order."""
    if all(source_index.get(n) is not None for n in names):
        ordered = sorted(names, key=lambda n: (source_index[n], n))
        return ordered, {n: float(source_index[n]) for n in ordered}  # type: ignore[arg-type]
    ordered = sorted(names)
    return ordered, {n: float(k) for k, n in enumerate(ordered)}
