"""The id -> object name table of a label set: LiveScene ``mapping.yaml`` or CoNeRF ``mapping.yml``.

Both are ``{int_id: name}`` YAML mappings; LiveScene ids are the pixel values of
id maps (1-based, 0 is background), CoNeRF ids are 0-based class indices. The
canonical object order is that of increasing id, whatever the base.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from stages.scene import read_yaml_mapping
from stages.scene.dataset import names_read_alike, object_name_problem

from .errors import LabelError

NAME_TABLE_FILES = ("mapping.yaml", "mapping.yml")


@dataclass(frozen=True)
class NameTable:
    """Object ids and names in canonical (increasing id) order."""

    ids: tuple[int, ...]
    """Ids as the source writes them (pixel values, class indices)."""
    names: tuple[str, ...]
    """Object names aligned with ``ids``."""
    path: Path | None
    """The file the table came from; None when derived from the labels themselves."""

    def index_of_id(self) -> dict[int, int]:
        """Source id -> 1-based canonical object index."""
        return {i: k + 1 for k, i in enumerate(self.ids)}

    def index_of_name(self) -> dict[str, int]:
        """Object name -> 1-based canonical object index."""
        return {n: k + 1 for k, n in enumerate(self.names)}


def read_name_table(path: str | Path) -> NameTable:
    """Parse ``{int_id: name}``; errors name the file and the offending entry."""
    path = Path(path)
    raw = read_yaml_mapping(path, "{int_id: object_name}", error=LabelError)
    if not raw:
        raise LabelError(path, "the name table is empty", "write one line `<id>: <object name>` per object")
    items: list[tuple[int, str]] = []
    for key, value in raw.items():
        try:
            ident = int(key)
        except (TypeError, ValueError) as exc:
            raise LabelError(path, f"id {key!r} is not an integer", "write {int_id: object_name}") from exc
        if isinstance(value, bool):  # YAML reads yes / no / on / off / true / false unquoted as a boolean
            raise LabelError(path, f"id {ident}: YAML reads the name as the boolean {value}, not as words",
                             f"quote the name: `{ident}: 'yes'` (or whichever word it is)")
        if not isinstance(value, str | int | float) or not str(value).strip():
            raise LabelError(path, f"id {ident} has no object name ({value!r})",
                             "write `<id>: <object name>` (quote a name YAML reads otherwise: `1: 'null'`)")
        items.append((ident, str(value).strip()))
    items.sort()
    names = [n for _, n in items]
    for n in names:
        if (problem := object_name_problem(n)) is not None:
            raise LabelError(path, f"object name {n!r} {problem}", "name the object in words (e.g. 'top drawer')")
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise LabelError(path, f"object names {dupes} appear more than once", "give each object one unique name")
    if (problem := names_read_alike(names)) is not None:
        raise LabelError(path, problem, "rename one of them in words (e.g. 'left drawer')")
    return NameTable(ids=tuple(i for i, _ in items), names=tuple(names), path=path)


def find_name_table(candidates: list[Path]) -> Path | None:
    """The first ``mapping.yaml`` / ``mapping.yml`` found in the given folders."""
    for folder in candidates:
        for name in NAME_TABLE_FILES:
            if (folder / name).is_file():
                return folder / name
    return None
