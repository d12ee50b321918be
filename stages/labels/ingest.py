"""Ingest a label set in any supported format into canonical LiveScene masks.

Output (written atomically into ``out``)::

    masks/<fid>.npy   bool H x W x (objects + 1), background last, frame size
    mapping.yaml      {1: name, 2: name, ...} in canonical object order
    labels.json       coverage per object per frame, frames without masks,
                      unreliable frames (an object present on fewer than
                      H*W/300 pixels and under a quarter of its usual size:
                      its mask is too small to trust)

When the annotations cover only some frames, the others are filled by optical-flow
propagation (``missing_masks="propagate"``, the default; stages/labels/propagate_masks.py adds
confidence/, confidence.csv and propagation.json), left without masks ("leave") or refused
("refuse"). With every frame annotated the output is the same in every mode.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from tqdm import tqdm

from stages.scene import atomic_dir, frame_number_of, label_map_to_onehot, write_json, write_mask, write_yaml
from stages.scene.dataset import names_read_alike
from stages.scene.masks import UNRELIABLE_DIVISOR, USUAL_QUANTILE, USUAL_SHARE, unreliable_masks, usual_sizes

from . import mask_checks as checks
from .coco_labels import read_coco_labels
from .errors import LabelError
from .frame_set import read_frame_set
from .label_set import LabelSet
from .labelme_labels import is_labelme, read_labelme_labels
from .name_table import NameTable, find_name_table, read_name_table
from .npy_labels import read_npy_labels
from .object_folder_labels import object_folders, read_object_folder_labels
from .png_labels import read_png_labels
from .propagate_masks import propagate_missing
from .resize import resize_labels

LabelFormat = Literal["auto", "npy", "png", "coco", "labelme", "objects"]
MissingMasks = Literal["propagate", "leave", "refuse"]


@dataclass
class LabelsConfig:
    """What `livescene labels` ingests and where it writes."""

    input: Path
    """Mask folder (npy, png, LabelMe json), a folder holding masks/, or a COCO / LabelMe .json file."""
    frames: Path
    """FRAMES folder (images/ + frames.csv) whose frame ids and size the masks must match."""
    out: Path
    """LABELS folder to write."""
    format: LabelFormat = "auto"
    """Source format; auto looks at the files."""
    mapping: Path | None = None
    """Name table {id: name} (mapping.yaml or CoNeRF mapping.yml); default: found next to the input."""
    progress: bool = True
    """Show a progress bar."""
    missing_masks: MissingMasks = "propagate"
    """Frames no annotation covers: propagate the annotations to them by optical flow, leave them without
    masks (listed in frames_without_masks; the mask loss skips them), or refuse (docs/labels-states.md)."""


def detect_format(path: Path) -> tuple[str, Path]:
    """(format, the file or folder holding the labels)."""
    if path.is_file():
        if path.suffix.lower() != ".json":
            raise LabelError(path, "a single label file must be a COCO or LabelMe .json",
                             "pass the folder of masks, or --format")
        data = _peek_json(path)
        if isinstance(data, dict) and "annotations" in data and "images" in data:
            return "coco", path
        if is_labelme(data):
            return "labelme", path
        raise LabelError(path, "neither COCO (images/annotations/categories) nor LabelMe (shapes)",
                         "pass --format or convert the file")
    if not path.is_dir():
        raise LabelError(path, "label input not found", "pass a mask folder or a COCO/LabelMe json file")
    folder = path / "masks" if (path / "masks").is_dir() and _has_labels(path / "masks") else path
    counts = {ext: sum(p.suffix.lower() == f".{ext}" for p in _visible(folder)) for ext in ("npy", "png", "json")}
    present = [ext for ext, n in counts.items() if n]
    if not present and object_folders(folder):
        return "objects", folder
    if len(present) != 1:
        what = "no .npy, .png or .json masks" if not present else f"a mix of {', '.join(present)} files"
        raise LabelError(folder, f"cannot tell the label format: {what}",
                         "pass --format npy|png|coco|labelme|objects")
    ext = present[0]
    if ext == "json":
        jsons = sorted(p for p in folder.glob("*.json") if not p.name.startswith("."))
        if len(jsons) == 1 and not is_labelme(_peek_json(jsons[0])):
            return "coco", jsons[0]
        return "labelme", folder
    return ext, folder


def _visible(folder: Path) -> list[Path]:
    """The folder's entries but hidden ones (macOS's ``._`` copies, ``.DS_Store``)."""
    return [p for p in folder.iterdir() if not p.name.startswith(".")]


def _has_labels(folder: Path) -> bool:
    return (any(p.suffix.lower() in (".npy", ".png", ".json") for p in _visible(folder))
            or bool(object_folders(folder)))


def _peek_json(path: Path) -> object:
    try:
        return json.loads(path.read_text(encoding="utf-8-sig"))
    except (OSError, json.JSONDecodeError) as exc:
        raise LabelError(path, f"not readable JSON ({exc})", "repair or re-export the file") from exc


def open_label_set(config: LabelsConfig) -> LabelSet:
    """Read the source's name table and list its labelled frames (nothing rasterised yet)."""
    fmt, where = detect_format(config.input) if config.format == "auto" else (config.format, config.input)
    if fmt == "coco" and where.is_dir():
        jsons = sorted(p for p in where.glob("*.json") if not p.name.startswith("."))
        if len(jsons) != 1:
            raise LabelError(where, f"{len(jsons)} .json files; COCO needs exactly one", "pass the COCO file itself")
        where = jsons[0]
    if where.is_dir() and (where / "masks").is_dir() and _has_labels(where / "masks"):
        where = where / "masks"
    folder = where if where.is_dir() else where.parent
    table_path = config.mapping or find_name_table([folder, folder.parent])
    table: NameTable | None = read_name_table(table_path) if table_path is not None else None
    if fmt in ("npy", "png"):
        if table is None:
            raise LabelError(folder, f"{fmt} masks carry no object names and no mapping.yaml / mapping.yml was found "
                             "next to them", "pass --mapping mapping.yaml ({id: name})")
        return read_npy_labels(where, table) if fmt == "npy" else read_png_labels(where, table)
    if fmt == "coco":
        return read_coco_labels(where, table)
    if fmt == "objects":
        return read_object_folder_labels(where, table)
    if fmt == "labelme":
        files = [where] if where.is_file() else sorted(p for p in where.glob("*.json") if not p.name.startswith("."))
        if not files:
            raise LabelError(where, "no LabelMe .json files", "save the annotations with LabelMe into this folder")
        return read_labelme_labels(files, table)
    raise LabelError(config.input, f"unknown format {fmt!r}", "use auto, npy, png, coco, labelme or objects")


def _numbered_one_late(label_set: LabelSet, frames) -> str | None:
    """A note when every label file names a frame once its number is read one less (masks numbered from 1, as
    ffmpeg's image2 writes frames, against frames numbered from 0): each mask then lies on the frame after its own."""
    numbers = [frame_number_of(e.label_id) for e in label_set.entries]
    if not numbers or not all(n is not None and n >= 1 and frames.match(str(n - 1)) is not None for n in numbers):
        return None
    return ("Every label file matches a frame when its number is read one less: were the masks numbered from 1 while "
            "the frames start at 0? Then each mask is used on the frame after its own; renumber the masks from 0")


def ingest_labels(config: LabelsConfig) -> dict:
    """Ingest, write LABELS atomically and return the labels.json summary."""
    frames = read_frame_set(config.frames)
    label_set = open_label_set(config)
    if not label_set.names:
        raise LabelError(config.input, "the label set names no objects", "add at least one object")
    if (problem := names_read_alike(list(label_set.names))) is not None:  # COCO categories, LabelMe labels, folders
        raise LabelError(config.input, problem, "rename one of them in words (e.g. 'left drawer')")
    if not label_set.entries:
        raise LabelError(config.input, f"no {label_set.format} label files found",
                         "point --input at the masks, or pass the --format they are in")
    matched: dict[str, str] = {}
    unmatched: list[str] = []
    for entry in label_set.entries:
        fid = frames.match(entry.label_id)
        if fid is None:
            unmatched.append(entry.source)
            continue
        if fid in matched:
            raise LabelError(entry.source, f"frame {fid} is labelled twice (also by {matched[fid]})",
                             "keep one annotation per frame")
        matched[fid] = entry.source
    if unmatched and matched:  # recorded in labels.json too; said here because a typo in a name looks the same
        shown = ", ".join(unmatched[:3]) + (", ..." if len(unmatched) > 3 else "")
        late = _numbered_one_late(label_set, frames)
        print(f"{config.input}: {len(unmatched)} label file(s) match no extracted frame of {frames.root} and are left "
              f"out ({shown}); names must end in a frame's source index"
              + (f". {late}" if late else ""), file=sys.stderr)
    if not matched:
        raise LabelError(config.input, f"none of the {len(label_set.entries)} labelled frames matches a frame of "
                         f"{frames.root} (ids like {frames.frame_ids[:3]})",
                         "label the extracted frames; names must end in the frame's source index")
    missing = [f for f in frames.frame_ids if f not in matched]
    if missing and config.missing_masks == "refuse":
        shown = ", ".join(missing[:5]) + (", ..." if len(missing) > 5 else "")
        raise LabelError(config.input, f"{len(missing)} of {len(frames.frame_ids)} frames of {frames.root} have no "
                         f"annotation (frames {shown}) and --missing-masks refuse was given",
                         "annotate those frames, or drop --missing-masks refuse to propagate the annotated frames "
                         "to them by optical flow (or pass --missing-masks leave to train without their masks)")
    propagate = bool(missing) and config.missing_masks == "propagate"
    by_source = {e.source: e for e in label_set.entries}
    names = list(label_set.names)
    h, w = frames.height, frames.width
    min_pixels = h * w / UNRELIABLE_DIVISOR
    per_frame: dict[str, dict] = {}
    overlaps: dict[str, int] = {}
    src_sizes: set[tuple[int, int]] = set()
    annotated: dict[str, np.ndarray] = {}
    position = {f: i for i, f in enumerate(frames.frame_ids)}
    previous: tuple[str, np.ndarray] | None = None  # the last annotated frame, for the tracker checks
    neighbours: list[tuple[str, str]] = []  # annotated frames next to each other in FRAMES
    warnings: list[dict] = []  # docs/labels-states.md, "Tracker failures"
    anti_aliased: dict[str, float] = {}
    at_border: dict[str, set[str]] = {}

    def record(fid: str, labels: np.ndarray) -> None:
        pixels = np.bincount(labels.ravel(), minlength=len(names) + 1)[1:]
        per_frame[fid] = {"pixels": {n: int(p) for n, p in zip(names, pixels, strict=True)},
                          "coverage": {n: round(float(p) / (h * w), 6) for n, p in zip(names, pixels, strict=True)}}

    def unreliable() -> dict[str, list[str]]:
        """Frames (playback order) -> objects whose mask there is too small to trust (``unreliable_masks``)."""
        ids = [f for f in frames.frame_ids if f in per_frame]
        if not ids:
            return {}
        small = unreliable_masks(np.array([[per_frame[f]["pixels"][n] for n in names] for f in ids]), h, w)
        return {f: [n for n, s in zip(names, row, strict=True) if s] for f, row in zip(ids, small, strict=True)
                if row.any()}

    with atomic_dir(config.out, "labels", inputs=[config.input, config.frames, config.mapping],
                    legacy=["labels.json"]) as tmp:
        order = [f for f in frames.frame_ids if f in matched]
        for fid in tqdm(order, desc="labels", unit="frame", disable=not config.progress):
            entry = by_source[matched[fid]]
            label_map = entry.load()
            src_sizes.add(label_map.labels.shape[:2])
            labels = resize_labels(label_map.labels, (h, w), entry.source).astype(np.int64)
            write_mask(tmp, fid, label_map_to_onehot(labels - 1, len(names)))
            record(fid, labels)
            if previous is not None and position[fid] == position[previous[0]] + 1:
                neighbours.append((previous[0], fid))
                overlaps_then = checks.overlap_counts(previous[1], labels, len(names))
                warnings.extend(checks.identity_switches(previous[0], fid, overlaps_then, names, min_pixels))
            previous = (fid, labels)
            at_border[fid] = checks.border_objects(labels, names)
            if label_set.format == "png":  # an id map's values: anti-aliasing makes ids between ids on edges
                between, edges = checks.between_id_edges(labels)
                if edges and between >= checks.BETWEEN_SHARE * edges:
                    anti_aliased[fid] = round(between / edges, 3)
            if propagate:
                annotated[fid] = labels.astype(np.uint16)
            if label_map.overlap_pixels:
                overlaps[fid] = label_map.overlap_pixels
        write_yaml(tmp / "mapping.yaml", {k + 1: n for k, n in enumerate(names)})
        pixels = {f: per_frame[f]["pixels"] for f in order}
        # the unreliable rule's usual size, over the annotated frames
        usual = dict(zip(names, usual_sizes(np.array([[p[n] for n in names] for p in pixels.values()])).tolist(),
                         strict=True))
        warnings.extend(checks.sudden_changes(neighbours, pixels, at_border, names, min_pixels, usual, USUAL_SHARE))
        warnings.sort(key=lambda w: (position[w["frame"]], w["kind"], names.index(w["object"])))
        if anti_aliased:
            warnings.append({"kind": "anti_aliased", "frames": list(anti_aliased),
                             "share": max(anti_aliased.values())})
        summary = {
            "format": label_set.format,
            "input": str(config.input),
            "names_from": label_set.names_from,
            "source_ids": list(label_set.source_ids),
            "objects": names,
            "height": h,
            "width": w,
            "source_sizes": sorted([sw, sh] for sh, sw in src_sizes),
            "n_frames": len(frames.frame_ids),
            "n_labelled": len(order),
            "min_reliable_pixels": min_pixels,
            "unreliable_rule": f"an object present on fewer than H*W/{UNRELIABLE_DIVISOR} pixels and fewer than "
                               f"{USUAL_SHARE} of its usual size (the {USUAL_QUANTILE} quantile of its pixel counts "
                               "where visible)",
            "frames_without_masks": missing,
            "unreliable_frames": unreliable(),
            "overlap_pixels": overlaps,
            "labels_without_frame": unmatched,
            "frames": per_frame,
        }
        if warnings:  # written only when a check found something: clean masks give the same labels.json as before
            summary["mask_warnings"] = warnings
        if propagate:
            result = propagate_missing(tmp, frames, annotated, names, progress=config.progress,
                                       on_frame=lambda fid, lab: record(fid, lab.astype(np.int64)))
            for fid, sources in result.sources.items():
                per_frame[fid]["propagated_from"] = sources
                per_frame[fid]["confidence"] = round(result.mean_confidence[fid], 5)
            loo = result.report["leave_one_out"]
            summary.update({
                "frames_without_masks": [],
                "missing_masks": config.missing_masks,
                "annotated_frames": order,
                "propagated_frames": result.frames,
                "propagation": {"file": "propagation.json", "confidence_file": "confidence.csv",
                                "mean_confidence": result.report["mean_confidence"],
                                "leave_one_out_mean_iou": loo.get("mean_iou_all"),
                                "leave_one_out_n": loo.get("n", 0)},
                "unreliable_frames": unreliable(),
                "frames": {f: per_frame[f] for f in frames.frame_ids},
            })
            write_json(tmp / "propagation.json", result.report)
        write_json(tmp / "labels.json", summary)
    if warnings:
        print(f"{config.input}: {len(warnings)} warning(s) about the masks ({config.out / 'labels.json'}, "
              "mask_warnings; docs/labels-states.md, \"Tracker failures\"):", file=sys.stderr)
        for w in warnings[:10]:
            print(f"  {checks.warning_line(w)}", file=sys.stderr)
        if len(warnings) > 10:
            print(f"  ... and {len(warnings) - 10} more", file=sys.stderr)
    unseen = [n for n in names if not any(per_frame[f]["pixels"][n] for f in per_frame)]
    if unseen:  # the mask ids or the name table do not match, or the object never shows
        print(f"{config.input}: no mask shows {unseen} in any frame: {'it' if len(unseen) == 1 else 'they'} cannot be "
              "located (check the masks' ids against the name table)", file=sys.stderr)
    return summary
