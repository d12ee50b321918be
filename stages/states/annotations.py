"""Key-frame annotations in three formats, each value remembered with the file row it came from.

- ``livescene``: ``key_frame_value.yaml`` ``{<name>_<fid>: {object: value}}``, fid = source index
- ``conerf``: ``annotations.yml``, a list of ``{class: <id>, frame: <n>, value: <v in [-1, 1]>}`` whose class
  ids are named by ``mapping.yml`` (``{<index from 0>: name}``)
- ``csv``: columns ``frame, object, value``; frame is a source index or a frame name (``frame_00012.png``)

Rows are 1-based line numbers of the file, so an error can say where to look.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import yaml

from .errors import StateError

AnnotationFormat = Literal["auto", "livescene", "conerf", "csv"]


@dataclass(frozen=True)
class KeyValue:
    """One annotated value of one object at one source frame."""

    source_index: int
    """Index of the frame in the source video."""
    object: str
    """Object name."""
    value: float
    """Annotated value, in the file's own units (normalised later)."""
    row: int
    """1-based line of the file that holds it."""


@dataclass
class Annotations:
    """All key values of one file."""

    path: Path
    format: str
    values: list[KeyValue]
    default_range: tuple[float, float] | None = None
    """The range values are known to live in (CoNeRF: [-1, 1]); None = min-max of the key frames."""
    objects: list[str] | None = None
    """Objects the annotation's own name table declares (CoNeRF mapping.yml), when it has one."""


def detect_format(path: Path) -> str:
    if path.suffix.lower() in (".csv", ".tsv"):  # .tsv: a spreadsheet's tab-separated export
        return "csv"
    data = _compose(path)
    if isinstance(data, yaml.SequenceNode):
        return "conerf"
    return "livescene"


def read_annotations(path: str | Path, fmt: AnnotationFormat = "auto", names: dict[int, str] | None = None,
                     names_path: Path | None = None) -> Annotations:
    """Read key frames; ``names`` maps CoNeRF class ids to names (default: mapping.yml next to the file)."""
    path = Path(path)
    if not path.is_file():
        raise StateError(path, "key-frame file not found", "pass key_frame_value.yaml, annotations.yml or a CSV")
    fmt = detect_format(path) if fmt == "auto" else fmt
    if fmt == "livescene":
        return Annotations(path, fmt, _read_livescene(path))
    if fmt == "csv":
        return Annotations(path, fmt, _read_csv(path))
    if fmt == "conerf":
        if names is None:
            names_path = names_path or path.with_name("mapping.yml")
            names = read_class_names(names_path)
        values = _read_conerf(path, names, names_path)
        return Annotations(path, fmt, values, default_range=(-1.0, 1.0), objects=[names[k] for k in sorted(names)])
    raise StateError(path, f"unknown key-frame format {fmt!r}", "use auto, livescene, conerf or csv")


def read_class_names(path: Path) -> dict[int, str]:
    """``{id: name}`` of a mapping.yaml / mapping.yml."""
    if not path.is_file():
        raise StateError(path, "name table not found (CoNeRF annotations name objects by class id)",
                         "pass --mapping mapping.yml ({class id: name})")
    raw = yaml.safe_load(path.read_text()) or {}
    if not isinstance(raw, dict):
        raise StateError(path, "top level is not a mapping", "write {class id: object name}")
    out = {}
    for k, v in raw.items():
        try:
            out[int(k)] = str(v)
        except (TypeError, ValueError) as exc:
            raise StateError(path, f"id {k!r} is not an integer", "write {class id: object name}") from exc
    return out


def _compose(path: Path) -> yaml.Node | None:
    try:
        return yaml.compose(path.read_text(), Loader=yaml.SafeLoader)
    except yaml.YAMLError as exc:
        raise StateError(path, f"not valid YAML ({exc})", "repair the file") from exc


def _scalar(node: yaml.Node) -> Any:
    loader = yaml.SafeLoader("")
    return loader.construct_object(node, deep=True)


def _number(path: Path, row: int, what: str, raw: Any) -> float:
    try:
        value = float(raw)
    except (TypeError, ValueError) as exc:
        raise StateError(path, f"row {row}: {what}: value {raw!r} is not a number",
                         "write a number (0 = closed, 1 = open)") from exc
    if not math.isfinite(value):
        raise StateError(path, f"row {row}: {what}: value is {value}",
                         "write a finite number or drop the entry")
    return value


def _source_index(path: Path, row: int, raw: Any) -> int:
    if isinstance(raw, bool):
        raise StateError(path, f"row {row}: frame {raw!r} is not a frame index", "write the source frame index")
    if isinstance(raw, int):
        index = raw
    elif isinstance(raw, float):
        if not raw.is_integer():
            raise StateError(path, f"row {row}: frame {raw!r} is not a whole frame index", "write the source frame "
                             "index of the key frame (key frames are frames, not times)")
        index = int(raw)
    else:
        text = str(raw).strip()
        # only an image file's extension is dropped: "10.5" stays "10.5" (not a frame) rather than frame 10
        stem = Path(text).stem if Path(text).suffix.lower() in (".png", ".jpg", ".jpeg", ".npy") else text
        fid = stem.rsplit("_", 1)[-1] if text else ""  # the last "_" token, as frame_id_of, without its suffix cut
        if not fid.isdigit():
            raise StateError(path, f"row {row}: frame {raw!r} does not end in a frame number",
                             "name key frames <name>_<source index> (e.g. frame_00012) or give the index")
        index = int(fid)
    if index < 0:
        raise StateError(path, f"row {row}: frame index {index} is negative", "use the source video frame index")
    return index


def _read_livescene(path: Path) -> list[KeyValue]:
    root = _compose(path)
    if root is None:
        return []
    if not isinstance(root, yaml.MappingNode):
        raise StateError(path, "top level is not a mapping", "write {<name>_<fid>: {object: value}}")
    out = []
    for key_node, value_node in root.value:
        row = key_node.start_mark.line + 1
        key = _scalar(key_node)
        index = _source_index(path, row, key)
        if not isinstance(value_node, yaml.MappingNode):
            raise StateError(path, f"row {row}: entry {key!r} is not a mapping of object to value",
                             "write {<name>_<fid>: {object: value}}")
        for obj_node, val_node in value_node.value:
            vrow = obj_node.start_mark.line + 1
            obj = str(_scalar(obj_node)).strip()  # as the labels stage and the CSV reader take a name
            value = _number(path, vrow, f"frame {key!r}, object {obj!r}", _scalar(val_node))
            out.append(KeyValue(index, obj, value, vrow))
    return out


def _read_conerf(path: Path, names: dict[int, str], names_path: Path | None) -> list[KeyValue]:
    root = _compose(path)
    if root is None:
        return []
    if not isinstance(root, yaml.SequenceNode):
        raise StateError(path, "top level is not a list", "write - {class: <id>, frame: <n>, value: <v>} entries")
    out = []
    for item in root.value:
        row = item.start_mark.line + 1
        entry = _scalar(item)
        if not isinstance(entry, dict) or not {"class", "frame", "value"} <= set(entry):
            raise StateError(path, f"row {row}: entry needs class, frame and value", "write {class, frame, value}")
        try:
            cls = int(entry["class"])
        except (TypeError, ValueError) as exc:
            raise StateError(path, f"row {row}: class {entry['class']!r} is not an integer",
                             "write the class id of mapping.yml") from exc
        if cls not in names:
            raise StateError(path, f"row {row}: unknown object: class {cls} is not in {names_path} "
                             f"(ids {sorted(names)})", "add the class to mapping.yml or fix the id")
        index = _source_index(path, row, entry["frame"])
        value = _number(path, row, f"frame {entry['frame']!r}, object {names[cls]!r}", entry["value"])
        out.append(KeyValue(index, names[cls], value, row))
    return out


def _read_csv(path: Path) -> list[KeyValue]:
    with path.open(newline="", encoding="utf-8-sig") as fh:  # a spreadsheet's "CSV UTF-8" starts with a BOM
        reader = csv.DictReader(fh, delimiter="\t" if path.suffix.lower() == ".tsv" else ",")
        fields = [f.strip().lower() for f in (reader.fieldnames or [])]  # "Frame,Object,Value" as a sheet writes it
        if not {"frame", "object", "value"} <= set(fields):
            raise StateError(path, f"row 1: header {fields} lacks frame, object or value",
                             "write the header `frame,object,value`")
        reader.fieldnames = fields
        out = []
        for rec in reader:
            row = reader.line_num
            if not any((v or "").strip() for v in rec.values() if isinstance(v, str)):
                continue  # an empty row (",,": what a spreadsheet leaves below its data)
            obj = (rec.get("object") or "").strip()
            if not obj:
                raise StateError(path, f"row {row}: no object name", "name the object of every row")
            index = _source_index(path, row, _csv_frame(rec.get("frame")))
            value = _number(path, row, f"frame {rec.get('frame')!r}, object {obj!r}", (rec.get("value") or "").strip())
            out.append(KeyValue(index, obj, value, row))
    return out


def _csv_frame(raw: str | None) -> Any:
    """A CSV cell's frame: an index (``12``; ``12.0`` as a table library writes a column that once held a blank),
    a fractional number (refused as no frame by ``_source_index``) or a frame name."""
    text = (raw or "").strip()
    if text.isdigit():
        return int(text)
    try:
        return float(text)
    except ValueError:
        return text
