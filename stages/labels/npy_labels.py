"""LiveScene masks: ``masks/<fid>.npy``, bool ``H x W x (objects + 1)``, background last, channels by sorted id."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from stages.scene import frame_id_of

from .errors import LabelError
from .label_set import LabelEntry, LabelMap, LabelSet
from .name_table import NameTable


def read_npy_labels(folder: Path, table: NameTable) -> LabelSet:
    files = sorted(p for p in folder.glob("*.npy") if not p.name.startswith("."))  # no macOS ``._`` copies
    n = len(table.names)
    entries = [LabelEntry(frame_id_of(f.stem), str(f), _loader(f, n)) for f in files]
    return LabelSet("npy", table.names, str(table.path), table.ids, entries)


def _loader(path: Path, n_objects: int):
    def load() -> LabelMap:
        try:
            mask = np.load(path, allow_pickle=False)
        except (ValueError, OSError) as exc:
            raise LabelError(path, f"cannot read the mask ({exc})", "re-export it as a .npy bool array") from exc
        if mask.ndim != 3 or mask.shape[2] != n_objects + 1:
            raise LabelError(path, f"mask has shape {mask.shape}, expected H x W x {n_objects + 1} "
                             f"({n_objects} objects of the name table + background last)",
                             "re-export the masks with one channel per object plus background, or fix the table")
        objects = mask[..., :n_objects].astype(bool)
        count = objects.sum(axis=-1)
        # the last set channel wins, as when painting in canonical order
        last = n_objects - np.argmax(objects[..., ::-1], axis=-1)
        labels = np.where(count > 0, last, 0).astype(np.uint16)
        return LabelMap(labels, int(np.count_nonzero(count > 1)))

    return load
