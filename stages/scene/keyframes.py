"""``key_frame_value.yaml``: sparse annotated states ``{<name>_<fid>: {object: value}}``."""

from __future__ import annotations

import math
import re
from pathlib import Path

from .atomic_io import write_yaml
from .errors import SceneError
from .yaml_io import read_yaml_mapping


def frame_id_of(stem: str) -> str:
    """Frame id = last ``_``-separated token of an image stem (LiveScene convention)."""
    return Path(stem).stem.rsplit("_", 1)[-1]


_LAST_DIGITS = re.compile(r"(\d+)\D*$")


def frame_number_of(stem: str) -> int | None:
    """The frame number a file name carries: its frame id when that is all digits (``IMG_0012`` -> 12), else the
    last run of digits in the stem (``img12``, ``frame-12``, ``DSC-0012`` -> 12, as a camera or an export names
    them); None when the name has no digit."""
    fid = frame_id_of(stem)
    if fid.isdigit():
        return int(fid)
    m = _LAST_DIGITS.search(Path(stem).stem)
    return int(m.group(1)) if m else None


def read_key_frames(path: Path, object_names: list[str] | None = None) -> dict[str, dict[str, float]]:
    """Key frames keyed on frame id; values checked finite and objects checked known."""
    raw = read_yaml_mapping(path, "{<name>_<fid>: {object: value}}", missing_ok=True)
    out: dict[str, dict[str, float]] = {}
    for key, values in raw.items():
        fid = frame_id_of(str(key))
        if not isinstance(values, dict):
            raise SceneError(path, f"entry {key!r} is not a mapping of object to value",
                             "write {<name>_<fid>: {object: value}}")
        row: dict[str, float] = {}
        for obj, val in values.items():
            if object_names is not None and str(obj) not in object_names:
                raise SceneError(path, f"entry {key!r} names unknown object {obj!r}",
                                 f"use one of {object_names} (see mapping.yaml)")
            try:
                v = float(val)
            except (TypeError, ValueError) as exc:
                raise SceneError(path, f"entry {key!r}, object {obj!r}: value {val!r} is not a number",
                                 "write a number in [0, 1]") from exc
            if not math.isfinite(v):
                raise SceneError(path, f"entry {key!r}, object {obj!r}: value is {v}",
                                 "write a finite number or drop the entry")
            row[str(obj)] = v
        if fid in out and any(out[fid].get(k, v) != v for k, v in row.items()):
            raise SceneError(path, f"frame {fid} is annotated twice with different values",
                             "keep one value per object and frame")
        out.setdefault(fid, {}).update(row)
    return out


def write_key_frames(path: Path, key_frames: dict[str, dict[str, float]], prefix: str = "frame") -> None:
    data = {f"{prefix}_{fid}": {k: float(v) for k, v in vals.items()} for fid, vals in key_frames.items()}
    write_yaml(path, data)
