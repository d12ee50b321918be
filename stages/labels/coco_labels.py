"""COCO instance JSON: ``images``, ``categories`` and ``annotations`` with polygon or RLE segmentations."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from stages.scene import frame_id_of

from .coco_rle import decode_rle
from .errors import LabelError
from .label_set import LabelEntry, LabelMap, LabelSet, paint
from .name_table import NameTable
from .polygon_fill import fill_polygons, polygon_from_flat


def read_coco_labels(path: Path, table: NameTable | None) -> LabelSet:
    try:
        data = json.loads(path.read_text(encoding="utf-8-sig"))
    except (OSError, json.JSONDecodeError) as exc:
        raise LabelError(path, f"not readable JSON ({exc})", "re-export the COCO file") from exc
    if not isinstance(data, dict) or not all(isinstance(data.get(k), list) for k in ("images", "annotations",
                                                                                      "categories")):
        raise LabelError(path, "not a COCO file (needs lists 'images', 'annotations' and 'categories')",
                         "export instance segmentation in COCO format, or pass the right --format")
    categories: dict[int, str] = {}
    for i, cat in enumerate(data["categories"]):
        try:
            categories[int(cat["id"])] = str(cat["name"])
        except (KeyError, TypeError, ValueError) as exc:
            raise LabelError(path, f"categories[{i}] lacks an integer 'id' or a 'name'",
                             "give every category an id and a name") from exc
        if not categories[int(cat["id"])].strip():
            raise LabelError(path, f"categories[{i}] (id {cat['id']}) has an empty name", "name every category")
    shared = {n: [c for c, m in categories.items() if m == n] for n in categories.values()}
    shared = {n: ids for n, ids in shared.items() if len(ids) > 1}
    if shared:
        name, ids = next(iter(shared.items()))
        raise LabelError(path, f"categories {ids} share the name {name!r}", "give each object one category (merge "
                         "their annotations under one id) or distinct names")
    if table is not None:
        names, names_from = table.names, str(table.path)
        unknown = sorted(set(categories.values()) - set(names))
        if unknown:
            raise LabelError(path, f"categories {unknown} are not in {table.path} (objects {list(names)})",
                             "add them to the name table or drop their annotations")
        source_ids = table.ids
    else:
        ordered = sorted(categories.items())
        names, names_from = tuple(n for _, n in ordered), f"{path} categories"
        source_ids = tuple(i for i, _ in ordered)
    index_of_name = {n: k + 1 for k, n in enumerate(names)}
    index_of_cat = {cid: index_of_name[name] for cid, name in categories.items()}

    by_image: dict[int, list[tuple[int, dict[str, Any]]]] = {}
    for i, ann in enumerate(data["annotations"]):
        if not isinstance(ann, dict) or "image_id" not in ann or "category_id" not in ann:
            raise LabelError(path, f"annotations[{i}] lacks 'image_id' or 'category_id'", "re-export the COCO file")
        if int(ann["category_id"]) not in index_of_cat:
            raise LabelError(path, f"annotations[{i}] has category_id {ann['category_id']} that no category defines",
                             "add the category or drop the annotation")
        by_image.setdefault(int(ann["image_id"]), []).append((i, ann))
    entries = []
    image_ids = {str(img.get("id")) for img in data["images"] if isinstance(img, dict)}
    for image_id, anns in by_image.items():
        if str(image_id) not in image_ids:
            raise LabelError(path, f"annotations[{anns[0][0]}] has image_id {image_id} that no image defines "
                             f"({len(anns)} annotation(s) would be lost)", "add the image or drop its annotations")
    for j, img in enumerate(data["images"]):
        try:
            image_id, file_name = int(img["id"]), str(img["file_name"])
            height, width = int(img["height"]), int(img["width"])
        except (KeyError, TypeError, ValueError) as exc:
            raise LabelError(path, f"images[{j}] lacks id, file_name, height or width",
                             "re-export the COCO file with image sizes") from exc
        anns = by_image.get(image_id, [])
        where = f"{path} ({file_name})"
        entries.append(LabelEntry(frame_id_of(Path(file_name).stem), where,
                                  _loader(path, anns, index_of_cat, height, width)))
    return LabelSet("coco", tuple(names), names_from, tuple(source_ids), entries)


def _loader(path: Path, anns: list[tuple[int, dict[str, Any]]], index_of_cat: dict[int, int], height: int,
            width: int):
    def load() -> LabelMap:
        canvas = np.zeros((height, width), dtype=np.uint16)
        overlap = 0
        # paint in canonical order so that overlaps resolve the same way in every format
        for i, ann in sorted(anns, key=lambda a: index_of_cat[int(a[1]["category_id"])]):
            region = _segmentation_mask(path, i, ann.get("segmentation"), height, width)
            overlap += paint(canvas, region, index_of_cat[int(ann["category_id"])])
        return LabelMap(canvas, overlap)

    return load


def _segmentation_mask(path: Path, i: int, seg: Any, height: int, width: int) -> np.ndarray:
    where = f"annotations[{i}]"
    if isinstance(seg, list):
        try:
            polygons = [polygon_from_flat(p) for p in seg]
        except (TypeError, ValueError) as exc:
            raise LabelError(path, f"{where}: bad polygon ({exc})", "write polygons as [x1, y1, x2, y2, ...]") from exc
        return fill_polygons(polygons, height, width)
    if isinstance(seg, dict) and "counts" in seg:
        size = seg.get("size", [height, width])
        if [int(s) for s in size] != [height, width]:
            raise LabelError(path, f"{where}: RLE size {size} differs from the image size [{height}, {width}]",
                             "re-export the annotation at the image size")
        try:
            return decode_rle(seg["counts"], height, width)
        except (TypeError, ValueError) as exc:
            raise LabelError(path, f"{where}: bad RLE ({exc})", "re-export the mask as COCO RLE") from exc
    raise LabelError(path, f"{where}: segmentation is neither a polygon list nor an RLE dict",
                     "write 'segmentation': [[x1, y1, ...]] or {'counts': ..., 'size': [h, w]}")
