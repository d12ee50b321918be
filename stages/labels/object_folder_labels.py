"""One folder of binary masks per object: ``<input>/<object name>/frame_00012.png``.

What a segmenter run once per object leaves (a text-prompted segmenter asked for "fridge", then for "drawer"):
each PNG is that object's mask in one frame, any non-zero pixel (grey, colour or palette) being the object, or,
in a PNG that uses transparency (a cut-out), any opaque pixel. The
folder names are the object names; a ``mapping.yaml`` beside the folders fixes their order (its names must be the
folders'), otherwise the sorted folder names do. A frame is read only where every object has a mask for it (an
empty mask says "not visible"); a frame some objects have and others lack is refused, since a missing file could
mean either.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from stages.scene import frame_id_of, frame_number_of
from stages.scene.mask_images import object_region

from .errors import LabelError
from .label_set import LabelEntry, LabelMap, LabelSet, paint
from .name_table import NameTable
from .png_labels import JPEG_SUFFIXES, png_masks, read_mask_image


def object_folders(folder: Path) -> list[Path]:
    """Subfolders of ``folder`` that hold masks (PNG, or JPEG, which reading refuses; hidden folders left out)."""
    suffixes = (".png", *JPEG_SUFFIXES)
    return sorted(d for d in folder.iterdir() if d.is_dir() and not d.name.startswith(".")
                  and any(p.suffix.lower() in suffixes for p in d.iterdir()))


def read_object_folder_labels(folder: Path, table: NameTable | None) -> LabelSet:
    folders = {d.name: d for d in object_folders(folder)}
    if not folders:
        raise LabelError(folder, "no object folders of PNG masks", "put each object's masks in a folder named after it")
    if table is not None:
        names = list(table.names)
        extra, absent = sorted(set(folders) - set(names)), [n for n in names if n not in folders]
        if extra or absent:
            raise LabelError(table.path or folder, f"the name table and the mask folders differ (folders without a "
                             f"name: {extra}; names without a folder: {absent})",
                             "name each object's folder as in the table, or remove the table (the folders then name "
                             "the objects)")
        names_from, ids = str(table.path), table.ids
    else:
        names = sorted(folders)
        names_from, ids = f"{folder} (sorted folder names)", tuple(range(1, len(names) + 1))
    files = {name: _by_frame(folders[name]) for name in names}
    frames = sorted(set().union(*files.values()))
    partial = {f: [n for n in names if f not in files[n]] for f in frames if any(f not in files[n] for n in names)}
    if partial:
        frame, lacking = next(iter(partial.items()))
        raise LabelError(folders[lacking[0]], f"{len(partial)} frames have masks for some objects only (frame {frame} "
                         f"has none for {lacking})",
                         "give every object a mask for each annotated frame (an empty mask where it is not visible)")
    entries = [LabelEntry(frame, str(folder / "*" / files[names[0]][frame].name),
                          _loader([files[n][frame] for n in names])) for frame in frames]
    return LabelSet("objects", tuple(names), names_from, tuple(ids), entries)


def _by_frame(folder: Path) -> dict[str, Path]:
    """An object's masks keyed on their frame: its number where the name has one, so that folders padded or named
    differently (``frame_00004.png``, ``IMG_4.png``) pair up; two masks of one frame are refused."""
    out: dict[str, Path] = {}
    for path in png_masks(folder):
        number = frame_number_of(path.stem)
        key = str(number) if number is not None else frame_id_of(path.stem)
        if key in out:
            raise LabelError(folder, f"two masks name frame {key} ({out[key].name}, {path.name})",
                             "keep one mask per frame in each object's folder")
        out[key] = path
    return out


def _loader(paths: list[Path]):
    def load() -> LabelMap:
        canvas: np.ndarray | None = None
        overlap = 0
        for index, path in enumerate(paths, start=1):
            region = object_region(read_mask_image(path))
            if canvas is None:
                canvas = np.zeros(region.shape, np.uint16)
            elif region.shape != canvas.shape:
                raise LabelError(path, f"mask is {region.shape[1]}x{region.shape[0]}, the frame's other masks "
                                 f"{canvas.shape[1]}x{canvas.shape[0]}", "export every object's masks at one size")
            overlap += paint(canvas, region, index)  # a pixel two objects claim goes to the later one
        assert canvas is not None
        return LabelMap(canvas, overlap)

    return load
