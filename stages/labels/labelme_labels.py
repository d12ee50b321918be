"""LabelMe JSON (as CoNeRF annotates its masks): one file per frame, polygon (or rectangle) shapes named by label."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from stages.scene import frame_id_of

from .errors import LabelError
from .label_set import LabelEntry, LabelMap, LabelSet, paint
from .name_table import NameTable
from .polygon_fill import fill_polygons


def read_labelme_labels(files: list[Path], table: NameTable | None) -> LabelSet:
    docs = [(f, _load_json(f)) for f in files]
    if table is not None:
        names, names_from, source_ids = table.names, str(table.path), table.ids
    else:
        found = sorted({str(s.get("label")) for _, d in docs for s in d["shapes"] if isinstance(s, dict)})
        names, names_from, source_ids = tuple(found), "sorted LabelMe shape labels (no name table given)", ()
    index_of_name = {n: k + 1 for k, n in enumerate(names)}
    entries = [LabelEntry(frame_id_of(f.stem), str(f), _loader(f, d, index_of_name, table)) for f, d in docs]
    return LabelSet("labelme", tuple(names), names_from, tuple(source_ids), entries)


def is_labelme(data: Any) -> bool:
    return isinstance(data, dict) and isinstance(data.get("shapes"), list)


def _load_json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text(encoding="utf-8-sig"))
    except (OSError, json.JSONDecodeError) as exc:
        raise LabelError(path, f"not readable JSON ({exc})", "re-save the annotation with LabelMe") from exc
    if not is_labelme(data):
        raise LabelError(path, "not a LabelMe file (no 'shapes' list)", "save the annotation with LabelMe")
    for key in ("imageHeight", "imageWidth"):
        if not isinstance(data.get(key), int) or data[key] <= 0:
            raise LabelError(path, f"no positive integer {key!r}", "re-save the annotation with LabelMe")
    return data


def _loader(path: Path, data: dict[str, Any], index_of_name: dict[str, int], table: NameTable | None):
    def load() -> LabelMap:
        height, width = int(data["imageHeight"]), int(data["imageWidth"])
        shapes = []
        for i, shape in enumerate(data["shapes"]):
            where = f"shapes[{i}]"
            label = str(shape.get("label")) if isinstance(shape, dict) else None
            if label not in index_of_name:
                known = list(index_of_name)
                raise LabelError(path, f"{where} has label {label!r}, which is no object of "
                                 f"{table.path if table else 'the label set'} ({known})",
                                 "rename the shape or add the object to the name table")
            shapes.append((index_of_name[label], i, _shape_region(path, where, shape, height, width)))
        canvas = np.zeros((height, width), dtype=np.uint16)
        overlap = 0
        for index, _, region in sorted(shapes, key=lambda s: (s[0], s[1])):
            overlap += paint(canvas, region, index)
        return LabelMap(canvas, overlap)

    return load


def _shape_region(path: Path, where: str, shape: dict[str, Any], height: int, width: int) -> np.ndarray:
    kind = shape.get("shape_type") or "polygon"
    try:
        points = np.asarray(shape.get("points"), dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise LabelError(path, f"{where}: points are not numeric", "redraw the shape") from exc
    if points.ndim != 2 or points.shape[1] != 2 or not np.isfinite(points).all():
        raise LabelError(path, f"{where}: points are not a list of finite [x, y]", "redraw the shape")
    if kind == "polygon" and len(points) >= 3:
        return fill_polygons([points], height, width)
    if kind == "rectangle" and len(points) == 2:
        (x0, y0), (x1, y1) = points.min(axis=0), points.max(axis=0)
        return fill_polygons([np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])], height, width)
    raise LabelError(path, f"{where}: shape_type {kind!r} with {len(points)} points cannot be filled",
                     "draw objects as polygons (3+ points) or rectangles")
