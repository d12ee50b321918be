"""`livescene states`: key frames -> a normalised state for every object at every extracted frame.

Outputs (written atomically into ``out``)::

    states.csv             frame, source_index, object, value, is_key_frame
    states.json            method per object, ranges, leave-one-out error per object and method
    key_frame_value.yaml   the key frames, normalised, keyed on frame names
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from stages.labels.name_table import read_name_table
from stages.scene import atomic_dir, write_json, write_yaml
from stages.scene.key_frame_states import key_value_range

from .annotations import AnnotationFormat, Annotations, KeyValue, read_annotations
from .errors import StateError
from .frame_table import FrameTable, read_frame_table
from .interpolation import METHODS, interpolate, leave_one_out

STILL_SPAN = 0.1
"""An object whose normalised key values span less than this is named as barely moving: the capture does not
show its other states, so they cannot be learned (annotation noise alone spans a few hundredths)."""


@dataclass
class StatesConfig:
    """What `livescene states` reads, how it interpolates, where it writes."""

    key_frames: Path
    """key_frame_value.yaml, CoNeRF annotations.yml or a CSV (frame, object, value)."""
    frames: Path
    """FRAMES/frames.csv (or the FRAMES folder)."""
    out: Path
    """STATES folder to write."""
    format: AnnotationFormat = "auto"
    """Key-frame file format."""
    method: str = "pchip"
    """Interpolation method for every object without an override."""
    object_methods: dict[str, str] = field(default_factory=dict)
    """Per-object method overrides."""
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    """Fixed (lo, hi) per object ("*" = every object); others are min-max normalised over their key frames."""
    mapping: Path | None = None
    """Name table {id: name}: the objects the scene has (unknown and never-annotated objects are errors)."""
    allow_missing_frames: bool = False
    """Use key frames on frames the source does not have (beyond its end; for interpolation only) instead of
    failing; a key frame on a source frame that was not extracted is used without it."""


def load_objects(config: StatesConfig, annotations: Annotations) -> list[str] | None:
    if config.mapping is not None:
        if annotations.format == "conerf":
            return annotations.objects
        # read as the labels stage reads it (names stripped, checked), so both stages name the objects alike
        return list(read_name_table(config.mapping).names)
    return annotations.objects


def check_key_values(config: StatesConfig, ann: Annotations, frames: FrameTable,
                     objects: list[str] | None) -> dict[str, dict[int, KeyValue]]:
    """Group values by object and frame; reject unknown objects, conflicts, missing frames, unannotated objects."""
    names_file = config.mapping or (ann.path.with_name("mapping.yml") if ann.format == "conerf" else None)
    grouped: dict[str, dict[int, KeyValue]] = {}
    for kv in ann.values:
        if objects is not None and kv.object not in objects:
            raise StateError(ann.path, f"row {kv.row}: unknown object {kv.object!r} (objects of {names_file}: "
                             f"{objects})", "fix the name or add the object to the name table")
        # a key frame between extracted frames (subsampled video) still pins the curve; one outside the video cannot
        if not frames.in_source(kv.source_index) and not config.allow_missing_frames:
            known = frames.describe_source()
            raise StateError(ann.path, f"row {kv.row}: key frame {kv.source_index} ({kv.object}) is a frame that "
                             f"does not exist in {frames.path} ({known})",
                             "fix the frame index, re-extract the frames, or pass --allow-missing-frames")
        seen = grouped.setdefault(kv.object, {}).get(kv.source_index)
        if seen is not None and seen.value != kv.value:
            raise StateError(ann.path, f"rows {seen.row} and {kv.row}: key frame {kv.source_index} of {kv.object!r} "
                             f"has two different values ({seen.value} and {kv.value})",
                             "keep one value per object and frame")
        grouped[kv.object].setdefault(kv.source_index, kv)
    if objects is not None:
        never = [o for o in objects if o not in grouped]
        if never:
            raise StateError(ann.path, f"objects {never} of {names_file} are never annotated",
                             "give each object at least one key frame (two or more to interpolate)")
    if not grouped:
        raise StateError(ann.path, "no key frames", "annotate at least one key frame per object")
    return grouped


def object_range(config: StatesConfig, ann: Annotations, name: str, kvs: list[KeyValue]) -> dict:
    values = np.array([kv.value for kv in kvs])
    user = config.ranges.get(name, config.ranges.get("*"))
    if user is not None or ann.default_range is not None:
        lo, hi = user if user is not None else ann.default_range  # type: ignore[misc]
        source = "--range" if user is not None else f"{ann.format} convention"
        outside = [kv for kv in kvs if not lo <= kv.value <= hi]
        if outside:
            kv = outside[0]
            raise StateError(ann.path, f"row {kv.row}: value {kv.value} of {name!r} lies outside the range "
                             f"[{lo}, {hi}] ({source})", "fix the value or widen the range")
        return {"lo": float(lo), "hi": float(hi), "source": source}
    found = key_value_range(values.tolist())
    if found is None:
        raise StateError(ann.path, f"row {kvs[0].row}: {name!r} has the single value {values[0]} on every key "
                         "frame, which min-max normalisation cannot map to [0, 1]", f"pass --range {name}=LO,HI")
    lo, hi, source = found
    return {"lo": lo, "hi": hi, "source": source}


def compute_states(config: StatesConfig) -> dict:
    """Interpolate, write STATES atomically and return the states.json summary."""
    ann = read_annotations(config.key_frames, config.format, names_path=config.mapping)
    frames = read_frame_table(config.frames)
    objects = load_objects(config, ann)
    grouped = check_key_values(config, ann, frames, objects)
    order = objects if objects is not None else list(grouped)
    for key in list(config.object_methods) + [k for k in config.ranges if k != "*"]:
        if key not in order:
            raise StateError(config.key_frames, f"option names unknown object {key!r} (objects {order})",
                             "use an object name of the key frames / mapping")
    for method in [config.method, *config.object_methods.values()]:
        if method not in METHODS:
            raise StateError("--method", f"unknown method {method!r}", f"use one of {list(METHODS)}")

    x = frames.source_index.astype(np.float64)
    rows = []
    summary: dict = {"key_frames_file": str(config.key_frames), "format": ann.format, "frames_file": str(frames.path),
                     "n_frames": len(frames.names), "objects": order, "methods": {}, "ranges": {},
                     "n_key_frames": {}, "key_span": {}, "still": [], "leave_one_out": {}, "suggested_method": {},
                     "hold": "outside the annotated range every method holds the first / last key value"}
    normalised_keys: dict[int, dict[str, float]] = {}
    for name in order:
        kvs = sorted(grouped[name].values(), key=lambda kv: kv.source_index)
        rng = object_range(config, ann, name, kvs)
        span = rng["hi"] - rng["lo"]
        key_x = np.array([kv.source_index for kv in kvs], dtype=np.float64)
        key_y = np.array([(kv.value - rng["lo"]) / span for kv in kvs])
        method = config.object_methods.get(name, config.method)
        values = interpolate(key_x, key_y, x, method)
        is_key = np.isin(frames.source_index, key_x.astype(np.int64))
        for fname, src, v, k in zip(frames.names, frames.source_index, values, is_key, strict=True):
            rows.append((fname, int(src), name, float(v), bool(k)))
        for kx, ky in zip(key_x.astype(int), key_y, strict=True):
            normalised_keys.setdefault(int(kx), {})[name] = float(ky)
        loo = {}
        for m in METHODS:
            err = leave_one_out(key_x, key_y, m)
            loo[m] = {"mae": float(err.mean()) if err.size else None,
                      "max": float(err.max()) if err.size else None, "n": int(err.size)}
        scored = [m for m in METHODS if loo[m]["mae"] is not None]
        summary["methods"][name] = method
        summary["ranges"][name] = rng
        summary["n_key_frames"][name] = len(kvs)
        summary["key_span"][name] = float(key_y.max() - key_y.min())
        if summary["key_span"][name] < STILL_SPAN:
            summary["still"].append(name)
        summary["leave_one_out"][name] = loo
        summary["suggested_method"][name] = (min(scored, key=lambda m: (round(loo[m]["mae"], 12), m != "pchip"))
                                             if scored else None)
    table = pd.DataFrame(rows, columns=["frame", "source_index", "object", "value", "is_key_frame"])
    key_yaml = {frames.stem_of(i): normalised_keys[i] for i in sorted(normalised_keys)}
    with atomic_dir(config.out, "states", inputs=[config.key_frames, config.frames, config.mapping],
                    legacy=["states.json"]) as tmp:
        table.to_csv(tmp / "states.csv", index=False)
        write_yaml(tmp / "key_frame_value.yaml", key_yaml)
        write_json(tmp / "states.json", summary)
    return summary


def read_states_csv(path: str | Path) -> pd.DataFrame:
    """states.csv as written by :func:`compute_states` (checked for the columns `livescene dataset assemble` needs)."""
    path = Path(path)
    if path.is_dir():
        path = path / "states.csv"
    if not path.is_file():
        raise StateError(path, "states.csv not found", "run `livescene states` first")
    # object names as written: pandas would read "null", "NA" or "None" as a missing value and "2" as a number
    table = pd.read_csv(path, dtype={"frame": str, "object": str}, keep_default_na=False)
    missing = [c for c in ("frame", "object", "value") if c not in table.columns]
    if missing:
        raise StateError(path, f"columns {missing} missing", "regenerate it with `livescene states`")
    bad = ~np.isfinite(pd.to_numeric(table["value"], errors="coerce").to_numpy(dtype=np.float64))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise StateError(path, f"row {i + 2}: value {table['value'].iloc[i]!r} is not a finite number",
                         "regenerate it with `livescene states`")
    return table
